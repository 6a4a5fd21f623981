"""Code that is not shipped in the extension: benchmarks, training and analytic test fields.

Imports ``engine`` (never the other way round); run it from the repository root, e.g.
``python -m lab bench``.
"""

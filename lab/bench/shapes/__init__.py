"""Seeded procedural ground-truth shapes, in metres: cars (closed multi-part), garments (open
tubes with layers), rooms (one-sided sheets and furniture). Each ``make_*(seed)`` returns
``(vertices (V, 3) float64, faces (F, 3) int64)``; :mod:`lab.bench.dataset` moves them to the
unit frame.
"""

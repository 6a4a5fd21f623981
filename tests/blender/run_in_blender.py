"""Run the Blender tests inside a real Blender: the arguments after ``--`` go to pytest.

    blender -b --factory-startup --python-exit-code 1 --python tests/blender/run_in_blender.py \
        -- tests/blender -q

With a window (no ``-b``, e.g. under ``xvfb-run``) the tests that need one (undo) run as well.
pytest must be importable by that Blender's Python. Exits with pytest's status.
"""

import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else ["tests/blender"]
os.chdir(ROOT)
# Blender's own pytest-unfriendly arguments stay out of pytest's way; the cache is not wanted.
code = int(pytest.main(["-p", "no:cacheprovider", *args]))
sys.stdout.flush()
sys.stderr.flush()
# sys.exit would leave a windowed Blender open; os._exit ends either kind with pytest's status.
os._exit(code)

# Blender-side tasks. BLENDER is a Blender 4.2+ binary, e.g.
#   make test-blender BLENDER=../shared/tools/real-blender/blender
#   make test-blender-gui BLENDER="../shared/tools/real-blender/shell.sh xvfb-run -a blender"
#   make build                      # dist/udf_reconstruction-<version>-linux_x64.zip

BLENDER ?= blender
PYTHON ?= .venv/bin/python
PYTEST_ARGS ?= tests/blender -q
# A throw-away Blender configuration inside the checkout (reachable from a chroot too).
USER_RESOURCES := $(CURDIR)/.cache/blender-user

.PHONY: test-blender test-blender-gui test-bpy build build-lean clean-user

test-blender: clean-user
	BLENDER_USER_RESOURCES=$(USER_RESOURCES) $(BLENDER) -b --factory-startup \
	    --python-exit-code 1 --python tests/blender/run_in_blender.py -- $(PYTEST_ARGS)

test-blender-gui: clean-user
	BLENDER_USER_RESOURCES=$(USER_RESOURCES) $(BLENDER) --factory-startup \
	    --python-exit-code 1 --python tests/blender/run_in_blender.py -- $(PYTEST_ARGS)

test-bpy:
	$(PYTHON) -m pytest $(PYTEST_ARGS)

build:
	$(PYTHON) tools/build_extension.py

build-lean:
	$(PYTHON) tools/build_extension.py --no-wheels

clean-user:
	rm -rf $(USER_RESOURCES)

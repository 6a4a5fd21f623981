# Blender-side tasks. BLENDER is a Blender 4.2+ binary, e.g.
#   make test-blender BLENDER=../shared/tools/real-blender/blender
#   make test-blender-gui BLENDER="../shared/tools/real-blender/shell.sh xvfb-run -a blender"
#   make build                      # dist/: a zip per platform and Python (3.11, 3.13), a lean one
#   make check-zip BLENDER=../shared/tools/real-blender/blender \
#       ZIP=dist/udf_reconstruction-<version>-linux_x64-python3.13.zip
#   make check-new-user BLENDER="../shared/tools/real-blender/shell.sh xvfb-run -a -s '-screen 0 1600x900x24' blender"
#   make check-ui BLENDER="../shared/tools/real-blender/shell.sh xvfb-run -a -s '-screen 0 1600x900x24' blender"

BLENDER ?= blender
PYTHON ?= .venv/bin/python
PYTEST_ARGS ?= tests/blender -q
# A throw-away Blender configuration inside the checkout (reachable from a chroot too).
USER_RESOURCES := $(CURDIR)/.cache/blender-user
# check-new-user: a second throw-away configuration, the cloud it imports, where the shots go.
NEW_USER_RESOURCES := $(CURDIR)/.cache/blender-newuser
NEW_USER_CLOUD ?= ../shared/data/real/cgal/b9_training.ply
NEW_USER_SHOTS ?= $(CURDIR)/.cache/new-user
NEW_USER_RESOLUTION ?= 64
VERSION := $(shell sed -n 's/^version = "\(.*\)"/\1/p' blender_manifest.toml)

# check-zip: the zip to install into a throw-away configuration, and its own user folder.
ZIP ?= dist/udf_reconstruction-$(VERSION)-linux_x64-python3.11.zip
ZIP_USER_RESOURCES := $(CURDIR)/.cache/blender-zipcheck
INSTALL_MISSING ?=
# check-ui: its throw-away configuration and where its screenshots go.
UI_USER_RESOURCES := $(CURDIR)/.cache/blender-ui
UI_SHOTS ?= $(CURDIR)/.cache/ui-check
UI_RESOLUTION ?= 128

.PHONY: test-blender test-blender-gui test-bpy build build-lean clean-user check-new-user check-zip check-ui

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

# Install the lean zip into a fresh user configuration of a windowed Blender, import a PLY,
# reconstruct, cancel, reconstruct, undo (tools/blender_new_user.py). Needs a window: xvfb-run.
check-new-user: build-lean
	rm -rf $(NEW_USER_RESOURCES)
	BLENDER_USER_RESOURCES=$(NEW_USER_RESOURCES) $(BLENDER) --factory-startup \
	    --python-exit-code 1 --python tools/blender_new_user.py -- \
	    dist/udf_reconstruction-$(VERSION).zip $(NEW_USER_CLOUD) $(NEW_USER_SHOTS) \
	    $(NEW_USER_RESOLUTION)

# Install ZIP into a fresh user configuration, enable it (with INSTALL_MISSING=1 pressing
# Install Missing Packages when something is missing) and reconstruct a sphere
# (tools/blender_zip_check.py).
check-zip:
	rm -rf $(ZIP_USER_RESOURCES)
	BLENDER_USER_RESOURCES=$(ZIP_USER_RESOURCES) $(BLENDER) --factory-startup --command \
	    extension install-file -r user_default $(ZIP)
	BLENDER_USER_RESOURCES=$(ZIP_USER_RESOURCES) $(BLENDER) -b --python-exit-code 1 \
	    --python tools/blender_zip_check.py -- $(if $(INSTALL_MISSING),--install-missing)

# Click through the artist's checks in a windowed Blender whose Python lacks scipy: missing
# package reported at the click, Install Missing Packages, a result in the source's child
# collection, a real scan with only actionable messages (tools/blender_ui_check.py). Needs a
# window (xvfb-run), xdotool and ImageMagick's import.
check-ui: build-lean
	rm -rf $(UI_USER_RESOURCES)
	BLENDER_USER_RESOURCES=$(UI_USER_RESOURCES) $(BLENDER) --factory-startup \
	    --python-exit-code 1 --python tools/blender_ui_check.py -- \
	    dist/udf_reconstruction-$(VERSION).zip $(NEW_USER_CLOUD) $(UI_SHOTS) $(UI_RESOLUTION)

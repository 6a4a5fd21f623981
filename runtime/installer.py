"""Install the missing Python packages into the extension's own user folder.

For a Blender whose Python no platform zip matches (a Linux distribution's build, a newer or
older Blender): Preferences has one button that runs pip, with Blender's own Python, as a child
process. pip installs into ``bpy.utils.extension_path_user(<extension>, path="site-packages")``,
which survives updates of the extension and needs no administrator rights. That folder is put on
``sys.path`` when the extension is enabled and as soon as an install succeeds, so Reconstruct
works at once, without a restart.

The packages are resolved against the numpy that Blender ships (a pip constraint), so their
binaries fit it; the copy of numpy pip puts beside them is removed again, so only Blender's is
ever loaded. A Blender without numpy (some Linux distributions' builds) gets numpy installed too.
"""

import importlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time

import bpy

from . import dependencies

# The top-level package of the extension (``bl_ext.<repo>.udf_reconstruction``).
EXTENSION = __package__.rsplit(".", 1)[0]
# What pip may install for each missing import name (the rest install by their install name).
PIP_NAMES = {"laspy": "laspy[lazrs]"}
# Not installed by the button: torch (for NVIDIA GPUs) is gigabytes and has its own install
# instructions per CUDA version.
NOT_INSTALLED = {"torch"}


def packages_folder(create: bool = False):
    """The folder the button installs into: this extension's user folder, ``site-packages``.
    None when the package is not loaded as an extension (the batch script imports a checkout
    as a plain package), which has no such folder."""
    if not EXTENSION.startswith("bl_ext."):
        return None
    return bpy.utils.extension_path_user(EXTENSION, path="site-packages", create=create)


def add_to_path() -> None:
    """Make the packages installed by the button importable (at enable time, and after an
    install). Appended, so Blender's own packages (numpy) always come first."""
    folder = packages_folder()
    if folder and os.path.isdir(folder) and folder not in sys.path:
        sys.path.append(folder)
        importlib.invalidate_caches()


def remove_from_path() -> None:
    folder = packages_folder()
    while folder and folder in sys.path:
        sys.path.remove(folder)


def to_install() -> list:
    """The pip requirements for the missing packages the button installs, in table order."""
    return [PIP_NAMES.get(module, distribution)
            for module, distribution, _, _ in dependencies.DEPENDENCIES
            if module not in NOT_INSTALLED and not dependencies.is_found(module)]


def python_binary() -> str:
    """Blender's Python interpreter (``sys.executable`` is it since Blender 2.91; a few builds
    report the Blender binary instead, whose Python then sits beside its prefix)."""
    if os.path.basename(sys.executable).lower().startswith("python"):
        return sys.executable
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    for name in (f"bin/python{version}", "bin/python3", "bin/python.exe", "python.exe"):
        candidate = os.path.join(sys.prefix, name)
        if os.path.isfile(candidate):
            return candidate
    return sys.executable


def _name(requirement: str) -> str:
    """The package name of a requirement: ``laspy[lazrs]==2.5.4`` -> ``laspy``."""
    return re.split(r"[<>=!~\[ ;]", requirement.strip())[0]


def _remove_numpy(folder: str) -> None:
    """Remove the numpy that pip installed beside the packages: Blender's is the one to use."""
    for name in os.listdir(folder):
        if re.fullmatch(r"numpy(\.libs|-[^/]+\.dist-info)?", name):
            shutil.rmtree(os.path.join(folder, name), ignore_errors=True)


class Install:
    """One pip run on a worker thread; ``text`` and ``fraction`` follow pip's output."""

    def __init__(self, requirements, folder, python=None):
        self.requirements = list(requirements)
        self.folder = folder
        self.python = python or python_binary()
        self.text = "Starting pip"
        self.fraction = 0.0
        self.output = []
        self.ok = None  # True / False once finished
        self.message = ""
        self.started = time.perf_counter()
        self.process = None
        self.cancelled = False
        self.thread = None
        self._collected = 0
        self._downloaded = 0
        self._requested = {_name(r) for r in self.requirements}
        self._seen = set()  # the requested packages pip has looked up so far
        # Blender's numpy, which the packages must fit (None: this Blender has none).
        try:
            import numpy
            self.numpy = numpy.__version__
        except ImportError:
            self.numpy = None

    def command(self, constraints: str) -> list:
        return [self.python, "-m", "pip", "install", "--target", self.folder, "--upgrade",
                "--only-binary=:all:", "--progress-bar", "off", "--disable-pip-version-check",
                "--no-input", "--constraint", constraints, *self.requirements]

    def _follow(self, line: str) -> None:
        """Turn one line of pip's output into ``text`` and ``fraction``."""
        line = line.strip()
        if not line:
            return
        self.output.append(line)
        found = re.match(r"Collecting (\S+)", line)
        if found:
            self._collected += 1
            name = _name(found.group(1))
            if name in self._requested and "(from " not in line:
                self._seen.add(name)
            self.text = "Looking up " + name
        found = re.match(r"(?:Downloading|Using cached) (\S+?)-\d\S*\.whl(?: \((.+)\))?", line)
        if found:
            self._downloaded += 1
            size = f" ({found.group(2)})" if found.group(2) else ""
            self.text = f"Downloading {found.group(1).replace('_', '-')}{size}"
        if line.startswith("Installing collected packages"):
            self.text = "Installing"
            self.fraction = max(self.fraction, 0.9)
        else:
            # Downloads so far against those known to come: the files pip looked up and the
            # requested packages it has not reached yet (their dependencies are not known yet).
            coming = self._collected + len(self._requested - self._seen)
            self.fraction = max(self.fraction, 0.85 * self._downloaded / max(coming, 1))

    def run(self) -> None:
        os.makedirs(self.folder, exist_ok=True)
        try:
            with tempfile.TemporaryDirectory(prefix="udfr_pip_") as tmp:
                constraints = os.path.join(tmp, "constraints.txt")
                with open(constraints, "w") as handle:
                    handle.write(f"numpy=={self.numpy}\n" if self.numpy else "")
                self.process = subprocess.Popen(
                    self.command(constraints), stdout=subprocess.PIPE,
                    stderr=subprocess.STDOUT, text=True, errors="replace")
                for line in self.process.stdout:
                    self._follow(line)
                code = self.process.wait()
        except OSError as error:
            self.ok, self.message = False, (f"Could not run Blender's Python ({error}). Install "
                                            f"the extension zip made for your Blender instead.")
            return
        if self.cancelled:
            self.ok, self.message = False, "Installing was cancelled."
        elif code != 0:
            self.ok, self.message = False, self._failure()
        else:
            if self.numpy:
                _remove_numpy(self.folder)
            add_to_path()
            missing = dependencies.missing_packages(optional=True)
            still = [name for name in self.requirements if _name(name) in missing]
            if still:
                self.ok, self.message = False, (
                    f"pip finished but {', '.join(still)} still cannot be found. Restart "
                    f"Blender and look at Preferences again.")
            else:
                seconds = time.perf_counter() - self.started
                self.ok, self.message = True, (
                    f"Installed {', '.join(self.requirements)} in {seconds:.0f} s. "
                    f"Reconstruct is ready; no restart needed.")
        self.fraction = 1.0

    def _failure(self) -> str:
        """What went wrong, from pip's last error line, and what to do."""
        errors = [line for line in self.output if line.startswith("ERROR")]
        reason = errors[-1][len("ERROR:"):].strip() if errors else \
            (self.output[-1] if self.output else "no output")
        if any("No module named pip" in line for line in self.output):
            reason = "Blender's Python has no pip"
        hint = "Check the internet connection" if any(
            re.search(r"(?i)connection|resolve|network|timed out", line)
            for line in self.output) else "See the system console for pip's output"
        return (f"Installing failed: {reason}. {hint}, or install the extension zip made for "
                f"your Blender.")

    def start_thread(self) -> None:
        self.thread = threading.Thread(target=self.run, name="udfr_pip", daemon=True)
        self.thread.start()

    def cancel(self) -> None:
        self.cancelled = True
        if self.process is not None and self.process.poll() is None:
            self.process.kill()

    @property
    def running(self) -> bool:
        return self.thread is not None and self.thread.is_alive()


_state = {"install": None, "result": None}  # the running Install; the last (ok, message)


def running_install():
    """The install in progress (for the preferences and the operator), or None."""
    return _state["install"]


def last_result():
    """``(ok, message)`` of the last install in this session, or None."""
    return _state["result"]


def start_install() -> Install:
    """A new install of the missing packages (:func:`to_install`); its thread not started yet."""
    _state["result"] = None
    _state["install"] = Install(to_install(), packages_folder(create=True))
    return _state["install"]


def end_install(install: Install) -> None:
    """Record the outcome of ``install`` (finished or cancelled); a new one may start. After a
    success the panel and the operators register, if they waited for numpy (see the extension's
    ``__init__``); that happens here, on the main thread."""
    _state["install"] = None
    if install.ok:
        importlib.import_module(EXTENSION).register_main()
    if install.ok is not None:
        _state["result"] = (install.ok, install.message)
        print("UDF Reconstruction: pip " + " ".join(install.requirements) + "\n  "
              + "\n  ".join(install.output[-40:]))

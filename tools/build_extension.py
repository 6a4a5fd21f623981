"""Build the extension zips: one per platform and Python version, each bundling its wheels.

    .venv/bin/python tools/build_extension.py              # every platform, Python 3.11 and 3.13,
                                                           # and the lean zip, into dist/
    .venv/bin/python tools/build_extension.py --platform linux-x64 --python-version 3.13
    .venv/bin/python tools/build_extension.py --no-wheels  # the lean zip only
    .venv/bin/python tools/build_extension.py --blender /path/to/blender   # no bpy module needed

Blender 4.2-5.0 run Python 3.11, Blender 5.1 and later (and Linux distributions' builds, e.g.
Debian's 4.3) run 3.13. Binary wheels fit one Python version, so every platform gets one zip per
version: ``dist/udf_reconstruction-<version>-<platform>-python3.13.zip``. Blender reads the Python
version from the wheels' names and refuses a zip made for another Python with "This Python version
(3.13) isn't compatible with (3.11)". The lean zip ``dist/udf_reconstruction-<version>.zip``
bundles nothing: it installs in any Blender, and its Preferences install what is missing.

Steps, per Python version: copy the extension's files (not the virtualenv, tests, docs, tools)
into a staging folder; ``pip download`` binary wheels of the engine's runtime requirements
(requirements.txt, environment markers evaluated for that Python and platform) and their
dependencies; drop numpy, which Blender ships (a second numpy would shadow Blender's for every
add-on), and torch (CUDA wheels are far over the size limit of extensions.blender.org; the
engine's networks run in numpy); check that every bundled wheel accepts the numpy Blender ships
with that Python; list the wheels and platforms in the staged manifest; then Blender's own
``extension build --split-platforms`` writes one zip per platform.
"""

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from email.parser import HeaderParser
from pathlib import Path

from packaging.requirements import Requirement
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
EXTENSION_ID = "udf_reconstruction"

# Blender platform -> the wheel platform tags pip may pick for it (Blender 4.2's minimums:
# glibc 2.28, macOS 11.2, Windows 10; scipy's Apple Silicon wheels need macOS 12).
PLATFORM_TAGS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "linux-arm64": ["manylinux_2_28_aarch64", "manylinux_2_17_aarch64", "manylinux2014_aarch64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": ["macosx_12_0_arm64", "macosx_11_0_arm64", "macosx_10_9_universal2"],
    "macos-x64": ["macosx_11_0_x86_64", "macosx_10_15_x86_64", "macosx_10_9_x86_64",
                  "macosx_10_9_universal2"],
}
# What environment markers see on each platform.
PLATFORM_MARKERS = {
    "linux-x64": {"sys_platform": "linux", "platform_system": "Linux",
                  "platform_machine": "x86_64", "os_name": "posix"},
    "linux-arm64": {"sys_platform": "linux", "platform_system": "Linux",
                    "platform_machine": "aarch64", "os_name": "posix"},
    "windows-x64": {"sys_platform": "win32", "platform_system": "Windows",
                    "platform_machine": "AMD64", "os_name": "nt"},
    "macos-arm64": {"sys_platform": "darwin", "platform_system": "Darwin",
                    "platform_machine": "arm64", "os_name": "posix"},
    "macos-x64": {"sys_platform": "darwin", "platform_system": "Darwin",
                  "platform_machine": "x86_64", "os_name": "posix"},
}
# The Python versions of Blender's builds, and the numpy versions those Blenders ship: 1.26 with
# Python 3.11 (Blender 4.2-5.0), numpy 2 with 3.13 (Blender 5.1+ and distributions' builds, e.g.
# Debian's Blender 4.3 with numpy 2.2). Wheels are resolved against the first (the oldest), and
# every bundled wheel must accept each of them.
BLENDER_NUMPY = {
    "3.11": ["1.26.4"],
    "3.13": ["2.1.0", "2.2.0", "2.3.0"],
}
PYTHON_VERSIONS = tuple(BLENDER_NUMPY)
# Packages Blender ships or the extension does not bundle (see the module docstring).
NOT_BUNDLED = {"numpy", "torch"}
# What gets copied for staging; Blender's build then applies the manifest's exclude patterns.
STAGE_SKIP = {".venv", ".git", ".cache", ".pytest_cache", "dist", "build", "out", "wheels",
              "tests", "docs", "tools", "benchmarks", "bench_results", "lab", "__pycache__"}


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def wheel_name(path) -> str:
    """The normalised distribution name of a wheel file: ``scikit_image-0.25.2-...`` ->
    ``scikit-image``."""
    return _normal(Path(path).name.split("-")[0])


def bundled_requirements(python_version: str, platform: str, path: Path = None) -> list:
    """The requirements from requirements.txt that apply to ``python_version`` on ``platform``
    (their markers evaluated there), minus what is not bundled; markers removed."""
    environment = {"python_version": python_version,
                   "python_full_version": python_version + ".0",
                   "implementation_name": "cpython",
                   "platform_python_implementation": "CPython",
                   **PLATFORM_MARKERS[platform]}
    requirements = []
    for line in (path or ROOT / "requirements.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if not line:
            continue
        requirement = Requirement(line)
        if requirement.marker is not None and not requirement.marker.evaluate(environment):
            continue
        if _normal(requirement.name) in NOT_BUNDLED:
            continue
        requirement.marker = None
        requirements.append(str(requirement))
    return requirements


def download_wheels(platform: str, python_version: str, folder: Path) -> list:
    """Binary wheels of the bundled requirements and their dependencies (numpy among them) for
    one platform and Python version, downloaded into the empty ``folder``. (pip's own cache makes
    a repeated download quick.)"""
    command = [sys.executable, "-m", "pip", "download", "--quiet", "--dest", str(folder),
               "--only-binary=:all:", "--implementation", "cp",
               "--python-version", python_version]
    for tag in PLATFORM_TAGS[platform]:
        command += ["--platform", tag]
    numpy = f"numpy=={BLENDER_NUMPY[python_version][0]}"  # so dependencies fit Blender's numpy
    subprocess.run(command + bundled_requirements(python_version, platform) + [numpy],
                   check=True)
    return sorted(folder.glob("*.whl"))


def numpy_conflicts(wheels, python_version: str) -> list:
    """``"<wheel> needs numpy<spec>"`` for each wheel whose numpy requirement refuses a numpy that
    Blender ships with ``python_version`` (:data:`BLENDER_NUMPY`)."""
    shipped = [Version(v) for v in BLENDER_NUMPY[python_version]]
    conflicts = []
    for path in wheels:
        with zipfile.ZipFile(path) as archive:
            metadata = next(n for n in archive.namelist()
                            if n.count("/") == 1 and n.endswith(".dist-info/METADATA"))
            headers = HeaderParser().parsestr(archive.read(metadata).decode("utf-8"))
        for line in headers.get_all("Requires-Dist") or []:
            requirement = Requirement(line)
            if _normal(requirement.name) != "numpy" or (
                    requirement.marker is not None
                    and not requirement.marker.evaluate({"extra": ""})):
                continue
            refused = [str(v) for v in shipped if v not in requirement.specifier]
            if refused:
                conflicts.append(f"{Path(path).name} needs numpy{requirement.specifier}, "
                                 f"Blender with Python {python_version} ships "
                                 f"{', '.join(refused)}")
    return conflicts


def stage_sources(stage: Path) -> None:
    def skip(folder, names):
        return [n for n in names if n in STAGE_SKIP or n.endswith((".zip", ".pyc"))]
    shutil.copytree(ROOT, stage, ignore=skip, symlinks=False)


def patch_manifest(stage: Path, wheels: list, platforms: list) -> None:
    """Add ``wheels`` and ``platforms`` to the staged manifest. No Blender version bounds: Blender
    reads the Python version from the wheels' names and refuses a zip made for another Python."""
    path = stage / "blender_manifest.toml"
    text = path.read_text()
    lines = []
    if wheels:
        lines.append("wheels = [\n" + "".join(f'  "./wheels/{w}",\n' for w in wheels) + "]")
        lines.append("platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]")
    first_table = text.index("\n[")
    path.write_text(text[:first_table] + "\n" + "\n".join(lines) + "\n" + text[first_table:])
    tomllib.loads(path.read_text())  # fail here, not in Blender, on a broken manifest


def blender_extension_command(args: list, blender: str) -> int:
    """Run ``blender --command extension ARGS`` with a binary, or through the bpy module."""
    if blender:
        return subprocess.run([blender, "--factory-startup", "--command", "extension", *args]
                              ).returncode
    import bpy  # noqa: F401  (puts Blender's scripts on sys.path)
    from bl_pkg import bl_extension_cli
    return bl_extension_cli.cli_extension_handler(args)


def build(output: Path, platforms: list, python_version, blender) -> list:
    """Build the zips of one Python version (None: the lean zip); return their paths."""
    with tempfile.TemporaryDirectory(prefix="udfr_build_") as tmp:
        stage = Path(tmp) / EXTENSION_ID
        built = Path(tmp) / "built"
        built.mkdir()
        stage_sources(stage)
        wheels = []
        if python_version is not None:
            (stage / "wheels").mkdir()
            for platform in platforms:
                folder = Path(tmp) / f"download-{platform}"
                folder.mkdir()
                for wheel in download_wheels(platform, python_version, folder):
                    if wheel.name not in wheels and wheel_name(wheel) not in NOT_BUNDLED:
                        shutil.copy2(wheel, stage / "wheels" / wheel.name)
                        wheels.append(wheel.name)
            conflicts = numpy_conflicts([stage / "wheels" / w for w in wheels], python_version)
            if conflicts:
                raise SystemExit("wheels that do not work with Blender's numpy:\n  "
                                 + "\n  ".join(conflicts))
            print(f"Python {python_version}: bundling {len(wheels)} wheels: {', '.join(wheels)}")
        patch_manifest(stage, wheels, platforms if wheels else [])
        command = ["build", "--source-dir", str(stage), "--output-dir", str(built)]
        if wheels:
            command.append("--split-platforms")
        if blender_extension_command(command, blender) != 0:
            raise SystemExit(f"Blender's extension build failed for Python {python_version}")
        zips = []
        for path in sorted(built.glob(f"{EXTENSION_ID}-*.zip")):
            name = path.name if python_version is None else \
                f"{path.stem}-python{python_version}.zip"
            zips.append(Path(shutil.move(path, output / name)))
        return zips


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--platform", action="append", choices=sorted(PLATFORM_TAGS),
                        help="platform to build for (repeatable; default: all)")
    parser.add_argument("--python-version", action="append", choices=PYTHON_VERSIONS,
                        help="Python of the target Blender (repeatable; default: all): "
                             "3.11 for Blender 4.2-5.0, 3.13 for 5.1 and later")
    parser.add_argument("--no-wheels", action="store_true",
                        help="only the lean zip, without dependency wheels (its Preferences "
                             "install what is missing)")
    parser.add_argument("--output-dir", default=str(ROOT / "dist"))
    parser.add_argument("--blender", help="a Blender binary to build with (default: bpy module)")
    args = parser.parse_args(argv)
    platforms = args.platform or sorted(PLATFORM_TAGS)
    output = Path(args.output_dir).resolve()
    output.mkdir(parents=True, exist_ok=True)

    versions = [] if args.no_wheels else (args.python_version or list(PYTHON_VERSIONS))
    if args.no_wheels or not (args.platform or args.python_version):
        versions.append(None)  # the lean zip
    for python_version in versions:
        for path in build(output, platforms, python_version, args.blender):
            print(f"{path}  {path.stat().st_size / 1e6:.1f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())

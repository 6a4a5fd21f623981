"""Build the extension zip(s): one per platform, each with that platform's dependency wheels.

    .venv/bin/python tools/build_extension.py                          # linux-x64, into dist/
    .venv/bin/python tools/build_extension.py --platform windows-x64 --platform macos-arm64
    .venv/bin/python tools/build_extension.py --no-wheels              # lean zip, no packages
    .venv/bin/python tools/build_extension.py --blender /path/to/blender   # no bpy module needed

Steps: copy the extension's files (not the virtualenv, tests, docs, tools) into a staging folder;
``pip download`` binary wheels of the engine's packages (versions pinned in requirements.txt) for
each platform and the Python of the target Blender (3.11 for Blender 4.2-5.0); drop numpy,
which Blender ships (a second numpy would shadow Blender's for every add-on) and torch (CUDA
wheels are far over the size limit of extensions.blender.org; the engine's networks run in numpy);
list the wheels and platforms in the staged manifest; then Blender's own ``extension build
--split-platforms`` writes ``dist/udf_reconstruction-<version>-<platform>.zip``. Downloads are
cached in ``.cache/wheels``.
"""

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Blender platform -> the wheel platform tags pip may pick for it (Blender 4.2's minimums:
# glibc 2.28, macOS 11.2, Windows 10).
PLATFORM_TAGS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "linux-arm64": ["manylinux_2_28_aarch64", "manylinux_2_17_aarch64", "manylinux2014_aarch64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_10_9_universal2"],
    "macos-x64": ["macosx_11_0_x86_64", "macosx_10_15_x86_64", "macosx_10_9_x86_64",
                  "macosx_10_9_universal2"],
}
# Packages Blender ships or the extension does not bundle (see the module docstring).
NOT_BUNDLED = {"numpy", "torch"}
# What gets copied for staging; Blender's build then applies the manifest's exclude patterns.
STAGE_SKIP = {".venv", ".git", ".cache", ".pytest_cache", "dist", "build", "out", "wheels",
              "tests", "docs", "tools", "benchmarks", "bench_results", "__pycache__"}


def bundled_requirements() -> list:
    """The pinned runtime requirements from requirements.txt, minus what is not bundled."""
    requirements = []
    for line in (ROOT / "requirements.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        name = re.split(r"[\[=<>!~ ]", line)[0].lower() if line else ""
        if name and name not in NOT_BUNDLED:
            requirements.append(line)
    return requirements


def download_wheels(platform: str, python_version: str) -> list:
    """Binary wheels of the bundled requirements and their dependencies for one platform."""
    cache = ROOT / ".cache" / "wheels" / f"{platform}-py{python_version}"
    cache.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "pip", "download", "--quiet", "--dest", str(cache),
               "--only-binary=:all:", "--implementation", "cp",
               "--python-version", python_version]
    for tag in PLATFORM_TAGS[platform]:
        command += ["--platform", tag]
    subprocess.run(command + bundled_requirements(), check=True)
    return sorted(p for p in cache.glob("*.whl")
                  if re.split(r"-", p.name)[0].lower().replace("_", "-") not in NOT_BUNDLED)


def stage_sources(stage: Path) -> None:
    def skip(folder, names):
        return [n for n in names if n in STAGE_SKIP or n.endswith((".zip", ".pyc"))]
    shutil.copytree(ROOT, stage, ignore=skip, symlinks=False)


def patch_manifest(stage: Path, wheels: list, platforms: list, python_version: str) -> None:
    """Add ``wheels``, ``platforms`` and the Blender versions whose Python fits the wheels."""
    path = stage / "blender_manifest.toml"
    text = path.read_text()
    lines = []
    if wheels:
        lines.append("wheels = [\n" + "".join(f'  "./wheels/{w}",\n' for w in wheels) + "]")
        lines.append("platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]")
        # Blender 4.2-5.0 run Python 3.11, 5.1 and later 3.13: binary wheels fit one of them.
        if python_version == "3.11":
            lines.append('blender_version_max = "5.1.0"')
        elif python_version == "3.13":
            text = re.sub(r'blender_version_min = "[^"]*"', 'blender_version_min = "5.1.0"', text)
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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--platform", action="append", choices=sorted(PLATFORM_TAGS),
                        help="platform to build for (repeatable; default linux-x64)")
    parser.add_argument("--python-version", default="3.11", choices=["3.11", "3.13"],
                        help="Python of the target Blender: 3.11 for 4.2-5.0 (default), "
                             "3.13 for 5.1 and later")
    parser.add_argument("--no-wheels", action="store_true",
                        help="one lean zip without dependency wheels (for a Blender whose "
                             "Python already has them)")
    parser.add_argument("--output-dir", default=str(ROOT / "dist"))
    parser.add_argument("--blender", help="a Blender binary to build with (default: bpy module)")
    args = parser.parse_args(argv)
    platforms = args.platform or ["linux-x64"]
    output = Path(args.output_dir).resolve()
    output.mkdir(parents=True, exist_ok=True)

    with tempfile.TemporaryDirectory(prefix="udfr_build_") as tmp:
        stage = Path(tmp) / "udf_reconstruction"
        stage_sources(stage)
        wheels = []
        if not args.no_wheels:
            (stage / "wheels").mkdir()
            for platform in platforms:
                for wheel in download_wheels(platform, args.python_version):
                    if wheel.name not in wheels:
                        shutil.copy2(wheel, stage / "wheels" / wheel.name)
                        wheels.append(wheel.name)
            print(f"bundling {len(wheels)} wheels: {', '.join(wheels)}")
        patch_manifest(stage, wheels, platforms, args.python_version)
        build = ["build", "--source-dir", str(stage), "--output-dir", str(output)]
        if wheels:
            build.append("--split-platforms")
        code = blender_extension_command(build, args.blender)
    for zip_path in sorted(output.glob("udf_reconstruction-*.zip")):
        print(f"{zip_path}  {zip_path.stat().st_size / 1e6:.1f} MB")
    return code


if __name__ == "__main__":
    sys.exit(main())

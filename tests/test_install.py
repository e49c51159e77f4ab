"""A regular install (`pip install .`, not editable) into a new environment runs the main job
from another folder: configs/ travels in the wheel, the console scripts find each other, and
`am-run` with no argument flies the default scenario to its verdict.

Slow (minutes: the build, the first compile of the kernels in the new environment, a whole
20 s mission), so marked `slow`: `pytest -m slow tests/test_install.py`. The new environment
takes this project's dependencies from the running interpreter's environment (a path file),
so the test needs no network for them; pip builds the wheel with its usual build isolation.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _site_packages(prefix: Path) -> Path:
    return Path(sysconfig.get_path("purelib", vars={"base": str(prefix), "platbase": str(prefix)}))


def _copy_tree(dst: Path) -> Path:
    """The project's tracked files (git ls-files), else the tree without runs/ and caches."""
    try:
        files = subprocess.run(["git", "-C", str(ROOT), "ls-files"], capture_output=True, text=True,
                               check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        shutil.copytree(ROOT, dst, ignore=shutil.ignore_patterns(".git", ".venv", "runs", "__pycache__", "*.egg-info",
                                                                 "build"))
        return dst
    for f in files:
        if (ROOT / f).is_file():
            (dst / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / f, dst / f)
    return dst


@pytest.mark.slow
def test_a_regular_install_runs_the_main_job_from_another_folder(tmp_path):
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    py = env_dir / "bin" / "python"
    # the dependencies: the running environment's site-packages, after the new one's own; its
    # .pth files are not processed, so its editable amstack (if any) stays out
    deps = Path(sysconfig.get_paths()["purelib"])
    lines = [str(deps)] + (["import cmeel_pth"] if (deps / "cmeel.pth").exists() else [])
    (_site_packages(env_dir) / "_amstack_test_deps.pth").write_text("\n".join(lines) + "\n")
    src = _copy_tree(tmp_path / "src")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    r = subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", str(src)], capture_output=True,
                       text=True, env=env, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    where = subprocess.run([str(py), "-c", "import amcore, amcore.config as c; print(amcore.__file__); "
                            "print(c.DEFAULT_SCENARIO)"], capture_output=True, text=True, env=env, cwd=elsewhere)
    amcore_file, default = where.stdout.split()
    assert Path(amcore_file).is_relative_to(env_dir), f"amcore imported from {amcore_file}, not the install"
    assert Path(default).is_file() and Path(default).is_relative_to(env_dir), default
    listed = subprocess.run([str(env_dir / "bin" / "am-run"), "--list"], capture_output=True, text=True, env=env,
                            cwd=elsewhere)
    assert listed.returncode == 0 and "two_am_comp_attitude" in listed.stdout, listed.stderr
    run = subprocess.run([str(env_dir / "bin" / "am-run"), "--no-progress", "--run-dir", "run"], capture_output=True,
                         text=True, env=env, cwd=elsewhere, timeout=1800)
    assert run.returncode == 0, run.stderr[-4000:]
    assert "verdict: mission success" in run.stderr
    manifest = json.loads((elsewhere / "run" / "manifest.json").read_text())
    assert manifest["scenario"] == "two_am_comp_attitude" and manifest["commit"] is None
    assert (elsewhere / "run" / "run.mcap").is_file() and (elsewhere / "run" / "keys").is_dir()

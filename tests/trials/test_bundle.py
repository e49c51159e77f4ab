"""A trial carries the files its scenario names (the vehicle TOML and its URDF), so a Dask
worker that cannot read the campaign's folder flies it all the same, bit for bit."""
from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

from amcore.config import read_scenario
from trials import cli
from trials.randomize import load_randomize
from trials.runner import bundle_files, run_all, run_trial, trial_folder

ROOT = Path(__file__).resolve().parents[2]
SHORT = ROOT / "configs" / "scenarios" / "two_am_short.toml"
DURATION_S = 0.5  # a trial cut short: enough to fly (its verdict then "incomplete", or "failed" if it failed early)


def _tasks(out: Path, n: int = 1):
    tasks = cli.build_tasks(read_scenario(SHORT), SHORT, load_randomize(cli.DEFAULT_RANDOMIZE), 3, n, out, None)
    short = []
    for t in tasks:
        data = {**t.data, "scenario": {**t.data["scenario"], "duration_s": DURATION_S}}
        short.append(replace(t, data=data))
    return short


def test_a_trial_bundles_its_vehicle_toml_and_urdf(tmp_path):
    (task,) = _tasks(tmp_path / "c")
    names = [rel for rel, _ in task.files]
    assert names == ["vehicle/am3dof.toml", "vehicle/am3dof.urdf"]
    for rel, blob in task.files:
        assert blob == (Path(task.path).parent / rel).read_bytes()
    assert bundle_files(task.data, Path(task.path)) == task.files


def test_without_its_folder_a_trial_loads_from_its_bundle(tmp_path):
    (task,) = _tasks(tmp_path / "c")
    shutil.rmtree(tmp_path / "c")
    with trial_folder(task) as where:
        assert where.name == Path(task.path).name and where.parent != Path(task.path).parent
        assert (where.parent / "vehicle" / "am3dof.urdf").is_file()
    assert not where.parent.exists()  # the temporary folder is gone afterwards


def test_a_dask_worker_elsewhere_flies_the_trial_without_the_campaign_folder(tmp_path, monkeypatch):
    """Workers started in another folder, the campaign's folder gone: the same state digest as
    the trial flown from its own files, and without its bundle the trial cannot load."""
    from dask.distributed import Client, LocalCluster

    (task,) = _tasks(tmp_path / "c")
    here = run_trial(task)
    assert here["verdict"] in ("incomplete", "failed"), here["reason"]  # flown (not refused, no error)
    shutil.rmtree(tmp_path / "c")
    elsewhere = tmp_path / "worker"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                      local_directory=str(elsewhere)) as cluster, Client(cluster) as client:
        assert client.run(lambda: __import__("os").getcwd()) == {w: str(elsewhere) for w in client.run(lambda: 0)}
        ex = client.get_executor()
        (row,) = run_all([task], ex)
        (bare,) = run_all([replace(task, files=())], ex)
    assert row["verdict"] == here["verdict"], row["reason"]
    assert row["state_digest"] == here["state_digest"]
    assert row["scenario_file"] == task.path
    assert bare["verdict"] == "error" and "file not found" in bare["reason"]

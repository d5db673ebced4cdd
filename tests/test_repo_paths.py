"""Paths in result files: relative to the repository where they lie inside it, as given
elsewhere, and read back to the same file (``study._io.repo_relative`` / ``repo_path``)."""

from __future__ import annotations

import os

from helpers import REPO
from study._io import REPO_ROOT, repo_path, repo_relative


def test_the_repository_root_is_the_checkout():
    assert REPO_ROOT == REPO.resolve()


def test_a_path_inside_the_repository_is_recorded_relative_to_it(monkeypatch, tmp_path):
    toml = REPO / "experiments" / "views.toml"
    assert repo_relative(toml) == "experiments/views.toml"
    assert repo_relative(str(toml)) == "experiments/views.toml"
    monkeypatch.chdir(tmp_path)  # a relative path is read against the working directory
    assert repo_relative(os.path.relpath(toml, tmp_path)) == "experiments/views.toml"
    monkeypatch.chdir(REPO / "experiments")
    assert repo_relative("views.toml") == "experiments/views.toml"


def test_a_path_outside_the_repository_is_kept_as_given(tmp_path):
    outside = tmp_path / "mine.toml"
    assert repo_relative(outside) == str(outside)
    assert repo_relative(str(outside)) == str(outside)


def test_a_recorded_path_reads_back_to_the_same_file(monkeypatch, tmp_path):
    toml = REPO / "experiments" / "views.toml"
    monkeypatch.chdir(tmp_path)  # from any working directory
    assert repo_path(repo_relative(toml)).resolve() == toml.resolve()
    assert repo_path(repo_relative(tmp_path / "x.toml")) == tmp_path / "x.toml"


def test_a_sweep_table_records_the_experiment_relative_to_the_repository(tmp_path):
    from study.sweep.scenes import scene_spec
    from study.sweep.table import job_columns

    inside = job_columns({"scene": scene_spec(REPO / "experiments" / "default.toml"), "seed": 1})
    assert inside["job.scene.experiment"] == "experiments/default.toml"
    assert inside["job.seed"] == 1
    outside = job_columns({"scene": scene_spec(tmp_path / "mine.toml")})
    assert outside["job.scene.experiment"] == str(tmp_path / "mine.toml")


def test_the_committed_results_name_no_folder_of_a_machine():
    # scripts/relative_result_paths.py rewrote them; it finds nothing more to rewrite
    import subprocess
    import sys

    res = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "relative_result_paths.py"), "--check"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0, res.stdout

"""The sweep engine: independent jobs (scene x shader variant x schedule x solver x start) as Dask
tasks on an embedded LocalCluster or an existing cluster, the render cache shared under locks,
and one tidy Parquet table per sweep that a re-run resumes.

``run_sweep(job_fn, jobs, table, scheduler=None, workers=None)`` runs them; job functions load
their scene with ``load_scene(job["scene"])``; ``scene_spec(path, overrides)`` names a scene.
"""

from .engine import run_sweep
from .scenes import load_scene, scene_spec
from .table import read_table, write_table

__all__ = ["run_sweep", "load_scene", "scene_spec", "read_table", "write_table"]

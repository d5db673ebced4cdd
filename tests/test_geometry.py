"""Analytic scene content: the wave field's components are distinct and drawing them ends."""

import subprocess
import sys

import numpy as np
import pytest

from helpers import REPO
from study.scene.geometry import MAX_COMPONENTS, Waves, wave_vector_bound

OFFSETS = [[0, 0], [0.31, 0.17], [0.53, 0.71], [0.13, 0.47]]


def test_every_component_count_ends_within_a_time_bound():
    """Up to 40 components fit the [-4, 4]^2 grid; 41..64 once looped forever there. In a
    subprocess with a timeout, so a hang fails the test instead of stalling the suite."""
    code = (
        "from study.scene.geometry import Waves\n"
        "for m in range(1, 65):\n"
        "    for seed in range(3):\n"
        "        Waves(0.05, 2.0, m, seed, [[0, 0]] * 4)\n"
        "print('done')\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0 and "done" in res.stdout, res.stderr


@pytest.mark.parametrize("m", [1, 5, 40, 41, 64])
def test_wave_vectors_are_distinct_up_to_sign_and_in_the_grid(m):
    w = Waves(0.05, 2.0, m, 3, OFFSETS)
    k = w.k.astype(int)
    assert len(k) == m and np.abs(k).max() <= wave_vector_bound(m)
    keys = {tuple(v) if (v[0], v[1]) > (0, 0) else tuple(-v) for v in k}
    assert len(keys) == m and (0, 0) not in keys
    assert w.a.sum() == pytest.approx(1.0)


def test_grid_bound_keeps_existing_fields_and_grows_beyond_40():
    assert [wave_vector_bound(m) for m in (1, 40, 41, 60, 64)] == [4, 4, 5, 5, 6]
    assert ((2 * wave_vector_bound(MAX_COMPONENTS) + 1) ** 2 - 1) // 2 >= MAX_COMPONENTS


def test_out_of_range_component_count_is_refused():
    with pytest.raises(ValueError, match="waves.components"):
        Waves(0.05, 2.0, MAX_COMPONENTS + 1, 0, OFFSETS)

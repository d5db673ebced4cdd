"""Small reference renders against golden EXRs
(regenerate: python tests/golden/reference_scenes.py)."""

import numpy as np
import pytest
from helpers.images import save_failure

from golden import reference_scenes as G

from study import read_exr  # noqa: E402


@pytest.mark.parametrize("name", list(G.SCENES))
def test_reference_matches_golden(mi, name):
    expected, prov, _ = read_exr(G.golden_path(name))
    exp = G.experiment(name)
    assert prov["scene_hash"] == exp.scene_hash(), (
        "scene changed on purpose? regenerate the goldens"
    )
    got = G.render(name).image
    rmse = float(np.sqrt(np.mean((got - expected) ** 2)))
    limit = G.SCENES[name][2] * prov["noise"]
    if not rmse <= limit:
        save_failure(
            f"reference_{name}", actual=got, expected=expected, error=np.abs(got - expected)
        )
    assert rmse <= limit, f"{name}: RMSE {rmse:.3e} > {limit:.3e} (images in tests/_failures/)"

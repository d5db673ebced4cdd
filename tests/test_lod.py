"""Level-of-detail policies (``study.studies.lod``): the band measures of a camera against their
closed forms, the policy front against brute force, and hand-checked cases where bands pay and
where they buy nothing."""

import itertools

import numpy as np
import pytest

from shaders_port.inputs import perspective_view_proj
from study.studies import lod

H = W = 32
COL = np.tile(np.arange(W, dtype=np.float64), (H, 1))  # a measure growing to the right


def _point(flip_map, fetches: float, seed: int) -> dict:
    noisy = flip_map + np.random.default_rng(seed).normal(0.0, 1e-3, flip_map.shape)
    return {"flip_map": noisy, "fetch_map": np.full((H, W), float(fetches)),
            "flip": float(noisy.mean()), "fetches_mean": float(fetches)}  # fmt: skip


def test_measures_of_a_camera_looking_straight_down():
    """Looking straight down from height h with a 90-degree field of view, a pixel covers
    (2h / W)^2 of the plane wherever it looks, and its distance is that of the plane point
    (x, z) = h * (ndc x, -ndc y) from the eye; from an oblique camera the footprint grows with
    the distance down the image's middle column."""
    h = 3.0
    vp = perspective_view_proj((0.0, h, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0), fov_y_deg=90.0)
    m = lod.band_measures(vp, (0.0, h, 0.0), W, H)
    np.testing.assert_allclose(m["footprint"], (2 * h / W) ** 2, rtol=1e-5)
    ndc = 2 * (np.arange(W) + 0.5) / W - 1
    x, z = np.meshgrid(ndc * h, ndc * h)  # row 0 at the top: the far side, -z up the image
    np.testing.assert_allclose(m["distance"], np.sqrt(h * h + x * x + z * z), rtol=1e-5)

    eye = (0.0, 1.5, 4.0)
    vp = perspective_view_proj(eye, (0.0, 0.0, 0.0), fov_y_deg=60.0)
    m = lod.band_measures(vp, eye, W, H)
    column = m["footprint"][:, W // 2]
    seen = np.isfinite(column)
    assert seen[-1] and not seen[0]  # the bottom row sees the water, the top the sky
    d = m["distance"][:, W // 2][seen]
    assert (np.diff(column[seen]) < 0).all() and (np.diff(d) < 0).all()  # nearer down the image


def test_the_footprint_is_the_central_difference_of_the_plane_points():
    """The closed-form footprint is the area spanned by the plane points' central differences
    a thousandth of a pixel either side, on every pixel that sees the water (an oblique
    camera: the footprint varies by orders of magnitude down the image)."""
    from shaders_port.pipeline.interpolate import plane_points

    eye = (0.5, 1.2, 4.0)
    vp = perspective_view_proj(eye, (0.0, -0.5, 0.0), fov_y_deg=50.0)
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float64)
    e = 1e-3

    def diff(dc, dr):
        a = plane_points(vp, W, H, cols + dc, rows + dr)[0]
        return (a - plane_points(vp, W, H, cols - dc, rows - dr)[0]) / (2 * e)

    fd = np.linalg.norm(np.cross(diff(e, 0), diff(0, e)), axis=-1)
    got = lod.footprint(vp, eye, W, H, cols, rows)
    seen = np.isfinite(lod.band_measures(vp, eye, W, H)["footprint"])
    assert seen.sum() > H * W // 3 and np.ptp(np.log(got[seen])) > 2.0
    np.testing.assert_allclose(got[seen], fd[seen], rtol=1e-5)  # truncation: ~1e-6


def test_two_bands_where_each_shader_wins_its_half():
    """A cheap shader as good as a dear one on the near half and bad on the far half: the
    policy is the cheap one near and the dear one far, split between the halves, at 0.6x the
    dear one's fetches; no single point reaches that FLIP cheaper than the dear one."""
    near = COL < 16
    pts = [
        _point(np.where(near, 0.1, 0.5), 2.0, 0),
        _point(np.full((H, W), 0.1), 10.0, 1),
        _point(np.full((H, W), 0.3), 1.0, 2),
    ]
    front = lod.policy_front(pts, {"distance": COL})
    found = lod.best_policy(front, pts, {"distance": COL}, 0.02)
    assert found["best"] == found["single"] == 1
    pol = found["policy"]
    assert pol["choices"] == [0, 1] and pol["bounds"] == [15.5] and pol["shares"] == [0.5, 0.5]
    assert pol["fetches"] == pytest.approx(6.0) and found["fetch_ratio"] == pytest.approx(0.6)
    assert abs(pol["d_flip"]) <= pol["se"]
    # chosen on half the blocks, it holds on the other half
    check = lod.held_out(pts, {"distance": COL}, 0.02)
    assert check["choices"] == [0, 1] and check["within"]
    assert check["fetch_ratio"] == pytest.approx(0.6)


def test_the_policy_is_weighed_against_the_cheapest_point_within_the_tolerance():
    """A point 1 % worse than the best at 0.7x its fetches is what a user would take (the
    tradeoff's 2 % tolerance): the policy is judged against it, FLIP and fetches."""
    near = COL < 16
    pts = [
        _point(np.where(near, 0.1, 0.5), 2.0, 0),
        _point(np.full((H, W), 0.1), 10.0, 1),
        _point(np.full((H, W), 0.101), 7.0, 2),
    ]
    found = lod.best_policy(lod.policy_front(pts, {"distance": COL}), pts, {"distance": COL},
                            0.02)  # fmt: skip
    assert found["best"] == 1 and found["single"] == 2
    assert found["single_d"][0] == pytest.approx(0.001, abs=1e-4)
    pol = found["policy"]
    assert pol["choices"] == [0, 2] and found["fetch_ratio"] == pytest.approx(4.5 / 7.0)
    assert pol["d_flip"] == pytest.approx(-0.0005, abs=2e-4)  # the near half is 0.1, not 0.101
    assert lod.best_policy([], pts, {"distance": COL}, 0.0)["single"] == 1


def test_bands_buy_nothing_where_one_shader_wins_everywhere():
    """The dear shader is better by far on every pixel: every policy that gives the cheap one
    a band is worse than the dear one by many standard errors, so there is none to take."""
    pts = [_point(np.full((H, W), 0.3), 2.0, 0), _point(np.full((H, W), 0.1), 10.0, 1)]
    front = lod.policy_front(pts, {"distance": COL})
    found = lod.best_policy(front, pts, {"distance": COL}, 0.02)
    assert found["single"] == 1 and found["policy"] is None and found["fetch_ratio"] is None
    assert any(len(p["choices"]) > 1 for p in front)  # mixed policies exist, all too poor
    assert lod.held_out(pts, {"distance": COL}, 0.02) is None


def test_the_front_is_the_brute_force_front(monkeypatch):
    """Band by band merging keeps exactly the front of every (bounds, choices) combination:
    three points with random maps, bounds at quartiles, up to three bands, two measures."""
    monkeypatch.setattr(lod, "QUANTILES", (0.25, 0.5, 0.75))
    rng = np.random.default_rng(7)
    pts = [{"flip_map": rng.uniform(0, 1, (H, W)), "fetch_map": rng.integers(1, 9, (H, W)) * 1.0}
           for _ in range(3)]  # fmt: skip
    measures = {"distance": COL, "footprint": rng.uniform(0, 1, (H, W))}
    got = sorted((round(p["fetches"], 9), round(p["flip"], 9))
                 for p in lod.policy_front(pts, measures, max_bands=3))  # fmt: skip
    combos = []
    n = H * W
    for m in measures.values():
        order = np.argsort(m.ravel(), kind="stable")
        f = np.stack([p["flip_map"].ravel()[order] for p in pts])
        c = np.stack([p["fetch_map"].ravel()[order] for p in pts])
        grid = [round(q * n) for q in (0.25, 0.5, 0.75)]
        for k in (1, 2, 3):
            for cuts in itertools.combinations(grid, k - 1):
                edges = (0, *cuts, n)
                for choice in itertools.product(range(3), repeat=k):
                    fs = sum(f[ch, a:b].sum() for ch, a, b in zip(choice, edges, edges[1:]))
                    cs = sum(c[ch, a:b].sum() for ch, a, b in zip(choice, edges, edges[1:]))
                    combos.append((cs / n, fs / n))
    front, best = [], np.inf
    for cost, flip in sorted(combos):
        if flip < best - 1e-12:
            front.append((round(cost, 9), round(flip, 9)))
            best = flip
    assert got == front


def test_a_policy_drawn_from_its_bounds_scores_what_the_front_says():
    """The bounds reproduce the front's split even where pixels tie on the measure (a view
    symmetric about its middle column: two pixels at each distance): the composite maps of
    every policy have the front's FLIP and fetches."""
    rng = np.random.default_rng(3)
    pts = [{"flip_map": rng.uniform(0, 1, (H, W)), "fetch_map": rng.integers(1, 9, (H, W)) * 1.0}
           for _ in range(3)]  # fmt: skip
    measures = {"distance": np.abs(COL - 15.5) + np.arange(H)[:, None] * 100.0}
    for pol in lod.policy_front(pts, measures, max_bands=3):
        flip, cost = lod.composite(pol, pts, measures)
        assert np.nanmean(flip) == pytest.approx(pol["flip"], rel=1e-12), pol
        assert np.nanmean(cost) == pytest.approx(pol["fetches"], rel=1e-12), pol

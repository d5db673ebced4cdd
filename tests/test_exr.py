"""EXR round trip with provenance; atomic writes."""

import os

import numpy as np
import pytest

from study import read_exr, write_exr


def test_round_trip_with_provenance(tmp_path):
    rng = np.random.default_rng(0)
    rgb = rng.random((7, 11, 3), dtype=np.float32) * 100
    var = rng.random((7, 11), dtype=np.float32)
    prov = {"key": "abc", "spp": 64, "noise": 0.0123456789, "versions": {"mitsuba": "3.9.1"}}
    se = rng.random((7, 11, 3), dtype=np.float32)
    p = write_exr(tmp_path / "a.exr", rgb, prov, extra={"var": var, "stderr": se})
    got, prov2, extra = read_exr(p)
    np.testing.assert_array_equal(got, rgb)
    np.testing.assert_array_equal(extra["var"], var)
    np.testing.assert_array_equal(extra["stderr"], se)
    assert prov2 == prov  # floats survive exactly (JSON text)
    assert [f for f in os.listdir(tmp_path)] == ["a.exr"]  # no temporary file left


def test_four_channels_round_trip(tmp_path):
    rgba = np.random.default_rng(1).random((5, 7, 4)).astype(np.float32)
    write_exr(tmp_path / "m.exr", rgba, {"what": "moments"})
    back, prov, extra = read_exr(tmp_path / "m.exr")
    np.testing.assert_array_equal(back, rgba)
    assert prov == {"what": "moments"} and extra == {}


def test_bad_shapes_and_files(tmp_path):
    with pytest.raises(ValueError, match=r"expected an \(H, W, 3\) or \(H, W, 4\) image"):
        write_exr(tmp_path / "b.exr", np.zeros((4, 4)))
    with pytest.raises(ValueError, match=r"got \(4, 4, 2\)"):
        write_exr(tmp_path / "b.exr", np.zeros((4, 4, 2)))
    with pytest.raises(ValueError, match="channel 'x' has shape"):
        write_exr(tmp_path / "b.exr", np.zeros((4, 4, 3)), extra={"x": np.zeros((3, 4))})
    assert not (tmp_path / "b.exr").exists()
    (tmp_path / "c.exr").write_bytes(b"not an exr at all")
    with pytest.raises(ValueError, match="not a readable EXR file"):
        read_exr(tmp_path / "c.exr")
    with pytest.raises(FileNotFoundError):
        read_exr(tmp_path / "missing.exr")


def test_failed_write_keeps_old_file(tmp_path, monkeypatch):
    p = write_exr(tmp_path / "d.exr", np.ones((2, 2, 3)), {"v": 1})
    import OpenEXR

    class Boom:
        def __init__(self, *a, **k):
            pass

        def write(self, path):
            with open(path, "wb") as f:
                f.write(b"partial")
            raise KeyboardInterrupt("killed mid-write")

    monkeypatch.setattr(OpenEXR, "File", Boom)
    with pytest.raises(KeyboardInterrupt):
        write_exr(p, np.zeros((2, 2, 3)), {"v": 2})
    monkeypatch.undo()
    rgb, prov, _ = read_exr(p)
    assert prov == {"v": 1} and rgb.min() == 1.0
    assert sorted(os.listdir(tmp_path)) == ["d.exr"]

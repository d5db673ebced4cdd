"""Property-based tests (hypothesis) of the two user inputs that are parsed: the experiment
schema (TOML tables and ``--set`` overrides) and the constants JSON file. Any input gives a
valid result or one clear error (``ExperimentError`` / ``ValueError``) that names the key at
fault and echoes a bad value clipped to a readable length; never another exception."""

from __future__ import annotations

import json
import math
import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from shaders_port import CONSTANT_SPECS
from study.export.shaders import load_constants_json
from study.config.experiment import SCHEMA, Experiment, ExperimentError, validate

MAX_MESSAGE = 1200  # characters: an error message stays readable
# long strings (thousands of characters), built cheaply: hypothesis draws big texts slowly
LONG = st.builds(
    lambda n, c: c * n,
    st.integers(600, 1200),
    st.sampled_from(["ab\u00e9\n\x00\"'", "x.y=", "[1,"]),
)
FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])

scalars = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.integers(min_value=-(2**2000), max_value=2**2000)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=20)
    | LONG
)
values = st.recursive(
    scalars,
    lambda c: st.lists(c, max_size=6) | st.dictionaries(st.text(max_size=8), c, max_size=4),
    max_leaves=12,
)
keys = st.sampled_from(sorted(SCHEMA)) | st.text(max_size=30) | LONG


def _nest(flat: dict) -> dict:
    """A flat {dotted key: value} as nested tables, as tomllib returns them."""
    out: dict = {}
    for k, v in flat.items():
        parts = k.split(".")
        d = out
        for p in parts[:-1]:
            nxt = d.setdefault(p, {})
            if not isinstance(nxt, dict):
                break
            d = nxt
        else:
            d[parts[-1]] = v
    return out


def _check_error(exc: Exception, key: str | None = None) -> None:
    msg = str(exc)
    assert msg and len(msg) <= MAX_MESSAGE, (len(msg), msg[:300])
    if key is not None:
        assert key[:80] in msg, (key[:80], msg[:300])


@FUZZ
@given(key=st.sampled_from(sorted(SCHEMA)), value=values)
def test_any_value_of_one_key_is_valid_or_an_error_naming_the_key(key, value):
    try:
        exp = validate(_nest({key: value}))
    except ExperimentError as exc:
        _check_error(
            exc,
            key
            if key not in ("resolution", "fit.resolution", "camera.position", "camera.target")
            else None,
        )
        return
    assert isinstance(exp, Experiment)
    assert set(exp.values) == set(SCHEMA)


@FUZZ
@given(raw=st.dictionaries(keys, values, max_size=6))
def test_any_table_is_valid_or_one_clear_error(raw):
    try:
        validate(_nest(raw))
    except ExperimentError as exc:
        _check_error(exc)


@FUZZ
@given(
    items=st.lists(
        st.text(max_size=60) | st.builds(lambda k, v: f"{k}={v}", keys, st.text(max_size=40)),
        max_size=4,
    )
)
def test_any_set_override_is_valid_or_one_clear_error(items):
    try:
        validate({}, items)
    except ExperimentError as exc:
        _check_error(exc)


def test_a_long_bad_value_is_clipped_in_the_message():
    long = "x" * 5000
    for item in (f"floor.shape={long}", f'water.ior="{long}"', f"{long}=1", long):
        with pytest.raises(ExperimentError) as err:
            validate({}, [item])
        _check_error(err.value)
        assert len(str(err.value)) < 700 and "more characters" in str(err.value)


# ---- constants JSON -----------------------------------------------------------------------

json_scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**2000), max_value=2**2000)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=20)
    | LONG
)
json_values = st.recursive(
    json_scalars,
    lambda c: st.lists(c, max_size=5) | st.dictionaries(st.text(max_size=8), c, max_size=3),
    max_leaves=10,
)
constant_names = st.sampled_from(sorted(CONSTANT_SPECS))


def _load(tmp_path, data, raw_text=None):
    p = tmp_path / "c.json"
    p.write_text(raw_text if raw_text is not None else json.dumps(data))
    return load_constants_json(p)


@FUZZ
@given(name=constant_names, value=json_values)
def test_any_constant_value_is_valid_or_an_error_naming_it(tmp_path_factory, name, value):
    tmp = tmp_path_factory.mktemp("c")
    for data in ({name: value}, {"constants": {name: value}, "experiment": "x"}):
        try:
            c = _load(tmp, data)
        except ValueError as exc:
            _check_error(exc, name)
            continue
        v = getattr(c, name)
        vals = v if isinstance(v, tuple) else (v,)
        assert all(math.isfinite(float(x)) for x in vals)


@FUZZ
@given(
    data=json_values
    | st.dictionaries(st.text(max_size=30) | constant_names, json_values, max_size=5),
    garbage=st.one_of(st.none(), st.text(max_size=50)),
)
def test_any_json_file_is_constants_or_one_clear_error(tmp_path_factory, data, garbage):
    tmp = tmp_path_factory.mktemp("c")
    try:
        _load(tmp, data, raw_text=garbage)
    except ValueError as exc:
        _check_error(exc)
        assert not re.search(r"Traceback", str(exc))

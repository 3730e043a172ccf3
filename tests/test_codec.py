"""How an estimate travels (`numerics.codec`): the quantized encoding is conservative
(what arrives dominates the sender's estimate, its rounding included), a relay changes
nothing, it counts its bytes as the encoder writes them, and a receiver refuses codes
that decode to no covariance."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import uavtrack
from uavtrack import radio
from uavtrack.agents.messages import Array, Part, Radio, Spec, encode, packed
from uavtrack.numerics import codec
from uavtrack.numerics.codec import COMPACT, QUANTIZED


@st.composite
def estimates(draw, count: int = 8):
    """Means within a large field and covariances of any scale (1e-4 to 1e6 m^2),
    correlations from none to nearly singular (a velocity that is almost the position's
    rate, as after long coasting)."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    mean = rng.uniform(-20_000, 20_000, (count, 4)) * np.array([1, 1, 1e-3, 1e-3])
    scale = 10.0 ** rng.uniform(-2, 3, (count, 1, 4))
    A = rng.normal(size=(count, 4, 4)) * scale
    near = draw(st.floats(0.0, 0.999999))
    A[:, :, 2:] = near * A[:, :, :2] + (1 - near) * A[:, :, 2:]  # correlated columns
    P = A @ np.swapaxes(A, -1, -2) + 1e-4 * np.eye(4)
    return mean, P


def dominance(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The largest generalized eigenvalue of P against Q (at most 1: Q >= P)."""
    inverse = np.linalg.inv(np.linalg.cholesky(Q))
    return np.linalg.eigvalsh(inverse @ P @ np.swapaxes(inverse, -1, -2))[..., -1]


@settings(max_examples=150, deadline=None)
@given(estimates())
def test_what_arrives_quantized_dominates_what_was_sent_rounding_included(drawn):
    mean, P = drawn
    got_mean, got_cov = QUANTIZED.delivered(mean, P)
    error = got_mean - mean  # the arriving mean's error is the estimate's less this
    assert (np.abs(error) <= np.abs(mean) * 2.0**-11 + 1e-7).all()  # float16's half ulp
    true = P + error[:, :, None] * error[:, None, :]
    assert (dominance(true, got_cov) <= 1.0 + 1e-8).all()
    assert (np.linalg.eigvalsh(got_cov)[:, 0] > 0).all()


@settings(max_examples=100, deadline=None)
@given(estimates())
def test_a_relay_passes_on_the_codes_it_got(drawn):
    # a receiver that adopts a tuple and sends it on sends the same codes
    mean, P = drawn
    first = QUANTIZED.pack(mean, P)
    again = QUANTIZED.pack(*QUANTIZED.unpack(first))
    for name in first:
        assert np.array_equal(first[name], again[name]), name


def test_without_the_dominance_step_the_rounding_alone_is_not_conservative():
    # the test above can fail: variances rounded up and correlations rounded to the
    # nearest code leave some covariances below the one they code
    rng = np.random.default_rng(5)
    A = rng.normal(size=(2000, 4, 4))
    P = A @ np.swapaxes(A, -1, -2) + 1e-3 * np.eye(4)
    sd = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1))
    C = P / (sd[:, :, None] * sd[:, None, :])
    corr = np.rint(C[:, [0, 0, 0, 1, 1, 2], [1, 2, 3, 2, 3, 3]] * codec.SCALE)
    var = np.ceil(np.log2(sd**2) * codec.STEPS)
    naive = codec.decoded_cov(var, corr)
    ok = np.linalg.eigvalsh(naive)[:, 0] > 0
    assert (dominance(P[ok], naive[ok]) > 1.0 + 1e-6).sum() > 100
    assert (dominance(P, QUANTIZED.delivered(np.zeros((2000, 4)), P)[1]) <= 1 + 1e-8).all()


def test_the_inflation_is_small_for_a_tracking_covariance():
    # a converged constant-velocity filter's covariance grows by a few percent
    P = np.array([[4.0, 0, 2.0, 0], [0, 4, 0, 2.0], [2.0, 0, 1.5, 0], [0, 2.0, 0, 1.5]])
    _, got = QUANTIZED.delivered(np.array([123.4, -45.6, 1.2, -0.5]), P)
    assert 1.0 < np.trace(got) / np.trace(P) < 1.05


def test_the_compact_codec_is_float32_and_the_upper_triangle():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(5, 4, 4))
    P, mean = A @ np.swapaxes(A, -1, -2), rng.normal(size=(5, 4)) * 100
    got_mean, got_cov = COMPACT.delivered(mean, P)
    assert np.array_equal(got_mean, radio.wire_mean(mean))
    assert np.array_equal(got_cov, radio.wire_cov(P))


@pytest.mark.parametrize("rows", [0, 1, 3, 4])
@pytest.mark.parametrize("tracked", [False, True])
def test_a_packed_content_is_counted_as_the_encoder_writes_it(rows, tracked):
    n, m, slots = 5, 4, (12 if tracked else 0)
    fields = radio.described("consensus", n, m, slots, tuples="quantized")
    layout = radio.layout("consensus", n, m, slots, tuples="quantized")
    assert set(layout) == ({radio.ROWS, "tombs"} if tracked else {radio.ROWS})
    rng = np.random.default_rng(rows)
    content = {}
    for name, (dtype, shape, _) in fields.items():
        size = (rows, *shape[1:]) if shape[:1] == (-1,) else shape
        content[name] = rng.integers(0, 100, size).astype(dtype)
    wire = radio.pack_rows(content, fields)
    body = encode(
        Radio(version=1, run="r", k=0, sender=0, parts=[Part("consensus", 1, -1, packed(wire))])
    )
    empty = encode(Radio(version=1, run="r", k=0, sender=0, parts=[Part("consensus", 1, -1, None)]))
    assert len(body) - len(empty) == int(radio.content_bytes(layout, rows)) - 1  # nil replaced
    back = radio.unpack_rows(wire[radio.ROWS], fields)
    for name, value in back.items():
        assert np.array_equal(value, content[name]) and value.dtype == content[name].dtype


def quantized_message(content: dict, k: int = 3) -> Radio:
    return Radio(
        version=1, run="r", k=k, sender=1, parts=[Part("consensus", 1, -1, packed(content))]
    )


@pytest.mark.parametrize("tracked", [False, True])
def test_codes_that_decode_to_no_covariance_are_refused(tracked):
    overrides = {"radio.encoding": "quantized"}
    if tracked:
        overrides |= {"tracker.association": "jpda"}
    spec = Spec.of(uavtrack.Scenario().with_overrides(overrides), central=False)
    fields = spec.contents("consensus")
    assert fields is not None
    P = np.array([[4.0, 0, 2.0, 0], [0, 4, 0, 2.0], [2.0, 0, 1.5, 0], [0, 2.0, 0, 1.5]])
    coded = QUANTIZED.pack(np.full((1, 4), 10.0), P[None])
    head = (
        {"slots": np.array([0], "<u2"), "label": np.array([1], "<u4")}
        if tracked
        else {"targets": np.array([0], "<u2"), "origin": np.array([1], "<u2")}
    )
    good = {**head, **coded, "stamp": np.array([3], "<i4")}
    if tracked:
        good["tombs"] = np.full((spec.slots, 2), -1, "<i4")
    good = {name: good[name] for name in fields}  # the declared order
    assert not isinstance(spec.radio(quantized_message(radio.pack_rows(good, fields)), 3), str)
    for change, reason in (
        ({"corr": np.full((1, 6), 127, "|i1")}, "covariance not positive definite"),
        ({"corr": np.full((1, 6), -128, "|i1")}, "correlation out of range"),
        ({"var": np.full((1, 4), 30000, "<i2")}, "covariance beyond the run's largest"),
        ({"mean": np.full((1, 4), np.inf, "<f2")}, "not finite"),
    ):
        bad = radio.pack_rows({**good, **change}, fields)
        assert spec.radio(quantized_message(bad), 3) == reason, change
    rows = radio.pack_rows(good, fields)[radio.ROWS]
    for wrong in (rows[:, :-1], rows.astype("<u2"), np.zeros((99, rows.shape[1]), "|u1")):
        content = {**radio.pack_rows(good, fields), radio.ROWS: wrong}
        message = Radio(
            version=1,
            run="r",
            k=3,
            sender=1,
            parts=[Part("consensus", 1, -1, {n: Array.of(v) for n, v in content.items()})],
        )
        assert spec.radio(message, 3) == "wrong shape or type"


def test_a_field_beyond_float16_is_refused_with_the_way_out():
    with pytest.raises(uavtrack.errors.ScenarioError, match="compact"):
        uavtrack.Scenario().with_overrides({"radio.encoding": "quantized", "field_size": 50_000})


def test_a_mean_beyond_float16_arrives_at_its_edge_with_the_difference_in_its_covariance():
    # a plausible estimate may lie past 65504 m (a large field, a long run): it is sent
    # finite, and what arrives still dominates what was sent
    mean, P = np.array([[66000.0, -70000.0, 1.0, 2.0]]), 100.0 * np.eye(4)[None]
    got_mean, got_cov = QUANTIZED.delivered(mean, P)
    assert np.isfinite(got_mean).all() and abs(got_mean[0, 0]) == codec.LARGEST
    error = got_mean - mean
    assert dominance(P + error[:, :, None] * error[:, None, :], got_cov)[0] <= 1 + 1e-8
    # variances past int16's codes: a tiny one is sent larger (conservative), a huge one
    # at the largest code, which no run's bounds admit
    _, got = QUANTIZED.delivered(np.zeros((2, 4)), np.stack([1e-40 * np.eye(4), 1e39 * np.eye(4)]))
    assert got[0, 0, 0] >= 1e-40 and got[1, 0, 0] > 1e38

"""The typed input boundary: the spacecraft configuration (processing.spacecraft) and the stream views
(processing.samples, TaskInputs accessors)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from processing.samples import GnssVisibilitySamples, GyroSamples, SamplesError, StarTrackerSamples
from processing.spacecraft import MissingMountingError, SolarPanel, Spacecraft, SpacecraftConfigError
from processing.tasks import TaskError, TaskInputs

S = 2 ** -0.5
CONFIG = {  # the README's example shape, with mountings given with q0 < 0 and not quite unit
    "star_trackers": {"st1": {"q_BS": [-S, 0.0, -S, 0.0]}, "st2": {"q_BS": [1, 0, 0, 0]}},
    "gyro": {"q_BG": [0.0, 0.0, 0.0, -1.0]},
    "magnetometer": {"q_BM": [1, 0, 0, 0]},
    "sun_sensor": {"q_BS": [0.5, 0.5, 0.5, 0.5]},
    "solar_panels": [{"normal_B": [2, 0, 0], "max_current_a": 1.2}, {"normal_B": [0, 1, 0], "max_current_a": 0.8}],
    "gnss_antenna_axis_B": [0, 0, -1],
    "inertia_kg_m2": [[51.44, 0, 0], [0, 51.48, 0], [0, 0, 0.76]],
    "specifications": {"ignored": "app-side"},
}


def test_a_missing_star_tracker_is_an_error_naming_it_and_the_configured_ones() -> None:
    sc = Spacecraft.from_json(CONFIG)
    with pytest.raises(MissingMountingError, match=r"star tracker 'st3' is not in the spacecraft configuration "
                                                   r"\(configured: st1, st2\)") as info:
        sc.star_tracker_mounting("st3")
    assert isinstance(info.value, TaskError) and isinstance(info.value, ValueError)
    with pytest.raises(MissingMountingError, match=r"'st1' .*\(configured: none\)"):
        Spacecraft().star_tracker_mounting("st1")


@pytest.mark.parametrize("method, names", [("magnetometer_mounting", "the magnetometer"),
                                           ("sun_sensor_mounting", "the sun sensor"),
                                           ("antenna_axis_B", "the GNSS antenna axis")])
def test_no_default_for_magnetometer_sun_sensor_and_antenna(method: str, names: str) -> None:
    sc = Spacecraft.from_json({"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}, "gyro": {}})
    with pytest.raises(MissingMountingError, match=f"{names} is not in the spacecraft configuration "
                                                   r"\(configured: star_trackers st1; gyro\)"):
        getattr(sc, method)()


def test_mountings_are_scalar_first_unit_canonical_and_read_only() -> None:
    sc = Spacecraft.from_json(CONFIG)
    q1 = sc.star_tracker_mounting("st1")
    assert q1.shape == (4,) and q1.dtype == np.float64
    np.testing.assert_allclose(q1, [S, 0.0, S, 0.0], atol=1e-15)  # same rotation, q0 >= 0
    np.testing.assert_allclose(sc.gyro_mounting(), [0.0, 0.0, 0.0, 1.0])  # q0 == 0: first non-zero made positive
    np.testing.assert_allclose(sc.sun_sensor_mounting(), [0.5, 0.5, 0.5, 0.5])
    for q in (q1, sc.gyro_mounting(), sc.magnetometer_mounting(), sc.sun_sensor_mounting()):
        assert q[0] >= 0 and abs(np.linalg.norm(q) - 1.0) < 1e-15
        with pytest.raises(ValueError, match="read-only"):
            q[0] = 0.5
    np.testing.assert_array_equal(sc.antenna_axis_B(), [0.0, 0.0, -1.0])
    np.testing.assert_array_equal(sc.panel_normals_B(), [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # unit normals
    np.testing.assert_array_equal(sc.panel_max_current_a(), [1.2, 0.8])
    assert sc.inertia_kg_m2 is not None and sc.inertia_kg_m2.shape == (3, 3)
    assert sc.star_tracker_names == ("st1", "st2") and sc.has_gyro
    with pytest.raises(dataclasses.FrozenInstanceError):
        sc.gyro_q_BG = None  # type: ignore[misc]
    with pytest.raises(TypeError):
        sc.star_trackers["st9"] = q1  # type: ignore[index]


def test_the_gyro_frame_is_the_body_frame_unless_configured() -> None:
    sc = Spacecraft.from_json({"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}})
    assert not sc.has_gyro
    np.testing.assert_array_equal(sc.gyro_mounting(), [1.0, 0.0, 0.0, 0.0])
    calibrated = Spacecraft.from_json(CONFIG).with_gyro_mounting([1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(calibrated.gyro_mounting(), [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(Spacecraft.from_json(CONFIG).gyro_mounting(), [0.0, 0.0, 0.0, 1.0])


@pytest.mark.parametrize("config, match", [
    ({"star_trackers": {"st1": {"q_BS": [0, 0, 0, 0]}}}, r"star_trackers\.st1\.q_BS must have unit norm"),
    ({"star_trackers": {"st1": {"q_BS": [1, 0, 0]}}}, r"star_trackers\.st1\.q_BS must be 4 finite numbers"),
    ({"star_trackers": {"st1": {}}}, r"star_trackers\.st1 has no q_BS"),
    ({"gyro": {"q_BG": [1, 0, float("nan"), 0]}}, r"gyro\.q_BG must be 4 finite"),
    ({"gnss_antenna_axis_B": [0, 0, 0]}, "gnss_antenna_axis_B must be non-zero"),
    ({"inertia_kg_m2": [1, 2, 3]}, r"inertia_kg_m2 must be finite numbers of shape \(3, 3\)"),
])
def test_malformed_values_are_errors_naming_the_key(config: dict, match: str) -> None:
    with pytest.raises(SpacecraftConfigError, match=match):
        Spacecraft.from_json(config)


def test_solar_panel_current_must_be_positive() -> None:
    with pytest.raises(SpacecraftConfigError, match="max_current_a must be > 0"):
        SolarPanel(np.array([1.0, 0.0, 0.0]), 0.0)


def _inputs(streams: dict) -> TaskInputs:
    return TaskInputs(streams=streams, spacecraft=Spacecraft(), start_tai_ns=0, end_tai_ns=10**10)


def test_typed_views_one_sensor_in_time_order() -> None:
    t = np.array([3, 1, 2, 5, 4], dtype=np.int64)
    sensor = np.array(["a", "a", "a", "b", "b"], dtype=object)
    st = {"time_tai_ns": t, "sensor": sensor, **{f"q{i}": t * 10.0 + i for i in range(4)}}
    gyro = {"time_tai_ns": t[:3], "sensor": np.full(3, "gyro", dtype=object),
            "wx": np.array([0.3, 0.1, 0.2]), "wy": np.zeros(3), "wz": np.ones(3)}
    inputs = _inputs({"star_tracker": st, "gyro": gyro})
    assert inputs.sensors("star_tracker") == ("a", "b") and inputs.sensors("magnetometer") == ()
    odd = _inputs({"gyro": {**gyro, "sensor": np.array([b"g2", 7, "g1"], dtype=object)}})
    assert odd.sensors("gyro") == ("7", "g1", "g2")  # names that are not str: as numpy's text of them, as before
    assert all(type(s) is str for s in odd.sensors("gyro") + inputs.sensors("star_tracker"))
    a = inputs.star_tracker("a")
    assert isinstance(a, StarTrackerSamples) and a.sensor == "a" and len(a) == 3
    np.testing.assert_array_equal(a.time_tai_ns, [1, 2, 3])
    np.testing.assert_array_equal(a.q_IS, [[10, 11, 12, 13], [20, 21, 22, 23], [30, 31, 32, 33]])  # q0 first
    assert a.time_tai_ns.dtype == np.int64 and a.q_IS.shape == (3, 4) and not a.q_IS.flags.writeable
    g = inputs.gyro()  # the only gyro
    assert isinstance(g, GyroSamples) and g.sensor == "gyro"
    np.testing.assert_array_equal(g.w_G_rad_s[:, 0], [0.1, 0.2, 0.3])
    with pytest.raises(TaskError, match=r"several star_tracker sensors in the window \(a, b\)"):
        inputs.star_tracker()
    with pytest.raises(TaskError, match="no magnetometer samples in the job window"):
        inputs.magnetometer()
    with pytest.raises(TaskError, match="no star_tracker samples of sensor 'c'"):
        inputs.star_tracker("c")


def test_view_columns_and_shapes_are_checked() -> None:
    vis = GnssVisibilitySamples.from_columns("rx", {"time_tai_ns": np.array([2, 1]), "system": np.array(["G", "E"]),
                                                    "prn": np.array([5, 7]), "visible": np.array([1, 0])})
    assert vis.system.tolist() == ["E", "G"] and vis.prn.dtype == np.int64 and vis.visible.tolist() == [False, True]
    with pytest.raises(SamplesError, match="gyro columns lack wz"):
        GyroSamples.from_columns("g", {"time_tai_ns": np.arange(2), "wx": np.zeros(2), "wy": np.zeros(2)})
    with pytest.raises(SamplesError, match=r"w_G_rad_s has shape \(2, 3\), expected 3 rows"):
        GyroSamples(sensor="g", time_tai_ns=np.arange(3), w_G_rad_s=np.zeros((2, 3)))


def test_sensor_index_gives_sorted_names_and_each_rows_position():
    from processing.samples import sensor_index

    column = np.array(["st2", "st1", "st2", "gyro", "st1"], dtype=object)
    names, index = sensor_index(column)
    assert names == ["gyro", "st1", "st2"] == sorted(set(column.tolist()))
    np.testing.assert_array_equal(np.array(names, dtype=object)[index], column)
    empty_names, empty_index = sensor_index(np.zeros(0, dtype=object))
    assert empty_names == [] and empty_index.size == 0

"""The failure table (quadcommon.failures): what is refused and how, PX4's words, the fault kinds."""

from pymavlink.dialects.v20 import common as mavlink

from quadcommon import failures
from quadcommon.failures import FAILURES, UNMODELLED, Refusal, Type, Unit, Where


def test_the_units_and_types_are_mavlinks_with_px4s_names():
    assert {u.value: u.name for u in Unit}[mavlink.FAILURE_UNIT_SYSTEM_MAVLINK_SIGNAL] == "mavlink_signal"
    names = ["ok", "off", "stuck", "garbage", "wrong", "slow", "delayed", "intermittent"]
    assert [t.name for t in Type] == names
    assert {u.value for u in Unit} == set(mavlink.enums["FAILURE_UNIT"]) - {mavlink.FAILURE_UNIT_ENUM_END}
    assert set(FAILURES) | set(UNMODELLED) == set(Unit) and not set(FAILURES) & set(UNMODELLED)


def test_every_pair_is_modelled_or_refused_with_a_reason():
    for unit in Unit:
        for failure_type in Type:
            why = failures.refusal(unit, failure_type, 0)
            model = FAILURES.get(unit)
            if model is not None and failure_type in model.types:
                assert why is None, (unit, failure_type)
            else:
                assert why is not None and why[0] is Refusal.UNSUPPORTED and unit.name in why[1]
    assert failures.refusal(200, 1, 0)[0] is Refusal.UNSUPPORTED  # no such unit
    assert failures.refusal(Unit.gps, 9, 0)[0] is Refusal.UNSUPPORTED  # no such type
    assert "modelled: ok, off, stuck, wrong" in failures.refusal(Unit.motor, Type.garbage, 0)[1]


def test_instances_beyond_the_units_are_denied():
    assert failures.refusal(Unit.motor, Type.off, 4) is None
    assert failures.refusal(Unit.motor, Type.off, 5)[0] is Refusal.DENIED
    assert failures.refusal(Unit.gps, Type.off, 1) is None
    kind, text = failures.refusal(Unit.gps, Type.off, 2)
    assert kind is Refusal.DENIED and "no instance 2" in text


def test_announcements_are_worded_as_px4s():
    assert failures.announcement(Unit.gps, Type.off, 0) == "Injected: gps off, all instances"
    assert failures.announcement(Unit.motor, Type.off, 2) == "Injected: motor off, instances 2"
    assert failures.announcement(Unit.gps, Type.ok, 0) == "Cleared: gps, all instances"


def test_the_sensor_failures_are_the_fault_kinds_and_back():
    kinds = failures.sensor_fault_kinds()
    sensor_pairs = [(m.unit, t) for m in FAILURES.values() if m.where is Where.SENSORS for t in m.effects]
    assert len(kinds) == len(sensor_pairs) and "gps_off" in kinds and "baro_stuck" in kinds
    for kind, (unit, failure_type) in zip(kinds, sensor_pairs, strict=True):
        assert failures.effect_of_kind(kind)[:2] == (unit, failure_type)
    assert failures.effect_of_kind("gps_outage") is None and failures.effect_of_kind("motor_off") is None
    assert "gyro_delayed" not in kinds  # the IMU samples every frame: no delay modelled


def test_keep_active_expands_instances_and_clears():
    active: dict[str, str] = {}
    failures.keep_active(active, Unit.motor, Type.off, 0)
    assert active == {f"motor {n}": "off" for n in (1, 2, 3, 4)}
    failures.keep_active(active, Unit.motor, Type.ok, 3)
    failures.keep_active(active, Unit.gps, Type.stuck, 1)
    assert active == {"motor 1": "off", "motor 2": "off", "motor 4": "off", "gps": "stuck"}
    failures.keep_active(active, Unit.gps, Type.ok, 0)
    assert "gps" not in active


def test_the_markdown_table_has_a_row_per_pair():
    table = failures.markdown_table()
    rows = [line for line in table.splitlines()[2:]]
    assert len(rows) == sum(len(m.effects) for m in FAILURES.values()) + len(UNMODELLED)
    assert "| `delayed` |" in table and "`servo` (102)" in table

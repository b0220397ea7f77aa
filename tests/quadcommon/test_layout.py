"""Record layouts: offsets generated from the declaration, refusals, the names a table carries, and
numba reading the offsets as constants (a compiled kernel that indexes by them)."""

from __future__ import annotations

import numpy as np
import pytest

from quadcommon.kernel import compiled, kernel
from quadcommon.layout import (
    Field,
    column_names,
    describe,
    fields_of,
    generated,
    layout,
    quaternion_at,
    reader,
    set_quaternion_at,
    set_vector_at,
    values,
    vector_at,
)

pytestmark = pytest.mark.timeout(120)

SETTINGS = layout(
    "Settings",
    (
        Field("dt", unit="s", doc="control period"),
        Field("home", 3, unit="deg, deg, m"),
        Field("final", elements=("x", "y", "z")),
    ),
)
EXTRA = layout("Extra", (Field("extra", unit="m"),), after=SETTINGS)


@kernel
def read_and_write(memory):
    memory[EXTRA.extra] = memory[SETTINGS.home + 2] + memory[SETTINGS.dt]
    return SETTINGS.size + EXTRA.size


def test_offsets_follow_the_declaration():
    assert (SETTINGS.dt, SETTINGS.home, SETTINGS.final, SETTINGS.size) == (0, 1, 4, 7)
    assert (EXTRA.extra, EXTRA.size) == (7, 8)
    assert [f.name for f in fields_of(SETTINGS)] == ["dt", "home", "final"]


def test_column_names_and_description():
    assert column_names(SETTINGS) == ("dt", "home_0", "home_1", "home_2", "final_x", "final_y", "final_z")
    assert column_names(EXTRA) == ("extra",)
    text = describe(SETTINGS)
    assert "home [deg, deg, m]" in text and "control period" in text and "(7 floats)" in text


@pytest.mark.parametrize(
    "fields, message",
    [
        ((Field("a"), Field("a")), "duplicate"),
        ((Field("size"),), "length"),
        ((Field("a", 0),), "size 0"),
        ((Field("a", 2, elements=("x", "y", "z")),), "elements"),
    ],
)
def test_bad_declarations_are_refused(fields, message):
    with pytest.raises(ValueError, match=message):
        layout("Bad", fields)


@kernel
def move_home(memory):
    """Home's vector shifted by one along each axis, and a quaternion at the final field's offset."""
    h = vector_at(memory, SETTINGS.home)
    set_vector_at(memory, SETTINGS.home, (h[0] + 1.0, h[1] + 1.0, h[2] + 1.0))
    q = quaternion_at(memory, SETTINGS.final)
    set_quaternion_at(memory, SETTINGS.final, (q[3], q[2], q[1], q[0]))
    return vector_at(memory, SETTINGS.home)


def test_a_fields_floats_are_read_and_written_at_its_offset_compiled_and_in_python():
    python, memory = np.arange(8.0), np.arange(8.0)
    assert move_home(python) == compiled(move_home)(memory) == (2.0, 3.0, 4.0)
    assert python.tolist() == memory.tolist() == [0.0, 2.0, 3.0, 4.0, 7.0, 6.0, 5.0, 4.0]


def test_compiled_code_reads_the_generated_offsets():
    memory = np.arange(8.0)
    entry = compiled(read_and_write)
    assert entry(memory) == 15
    assert memory[7] == 3.0 + 0.0  # home's third element (3) plus dt (0)


def test_values_are_ordered_by_the_layout_and_checked_by_name():
    assert values(SETTINGS, final=(7, 8, 9), dt=0.5, home=[1, 2, 3]) == (0.5, 1.0, 2.0, 3.0, 7.0, 8.0, 9.0)
    with pytest.raises(ValueError, match=r"unknown fields \['dtt'\], missing fields \['dt'\]"):
        values(SETTINGS, dtt=0.5, home=(1, 2, 3), final=(1, 2, 3))
    with pytest.raises(ValueError, match="home: 2 values for 3"):
        values(SETTINGS, dt=0.5, home=(1, 2), final=(1, 2, 3))


def test_a_reader_gives_the_named_fields_of_a_record_in_the_order_asked():
    read = reader(SETTINGS, ("final", "dt", "home"))
    memory = [0.5, 1.0, 2.0, 3.0, 7.0, 8.0, 9.0]
    assert read(memory) == ((7.0, 8.0, 9.0), 0.5, (1.0, 2.0, 3.0))
    assert reader(EXTRA, ("extra",))([*memory, 4.0]) == (4.0,)  # a layout after another: its offsets
    with pytest.raises(ValueError, match="Settings has no field 'speed'"):
        reader(SETTINGS, ("speed",))


def test_a_generated_read_builds_its_objects_from_the_fields_it_names():
    source = """
    def home_and_final(x, scale):
        if {dt} > 0.0:
            return Point(*{home}), scale * {final}[2]
        return None
    """
    read = generated(SETTINGS, source, {"Point": lambda *p: ("point", p)})
    memory = [0.5, 1.0, 2.0, 3.0, 7.0, 8.0, 9.0]
    assert read(memory, 2.0) == (("point", (1.0, 2.0, 3.0)), 18.0)
    assert read([-1.0, *memory[1:]], 2.0) is None
    with pytest.raises(ValueError, match="Settings has no field 'speed'"):
        generated(SETTINGS, "def f(x):\n    return {speed}\n", {})
    with pytest.raises(ValueError, match="not one function definition"):
        generated(SETTINGS, "x = {dt}", {})

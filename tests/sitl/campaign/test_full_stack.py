"""The full-stack check compares for real: a planted difference is reported, a wire-off spec refused."""

from dataclasses import replace

import pyarrow as pa
import pytest

pytest.importorskip("numba")

from sitl.campaign import batch, full_stack  # noqa: E402
from sitl.campaign.spec import load_campaign  # noqa: E402

from . import specs  # noqa: E402


@pytest.mark.timeout(300)
def test_a_planted_difference_is_reported_and_the_true_rows_agree(tmp_path):
    spec = load_campaign(specs.write(tmp_path, specs.WIND, "wind", duration=2.0), runs=2)
    rows = batch.run_chunk(spec, [1])  # wind: drag, 1-cos gusts, ramps, Dryden, initial velocity
    name = spec.controller_names[0]
    spec_one = replace(spec, controllers=spec.controllers[:1])
    table = pa.Table.from_pylist([r for r in rows if r["controller"] == name])
    (good,) = full_stack.check(spec_one, table, [1])
    assert good.agrees and good.worst_relative < 1e-9, good
    planted = [dict(r, ise_theta=r["ise_theta"] * (1 + 1e-4)) for r in table.to_pylist()]
    (bad,) = full_stack.check(spec_one, pa.Table.from_pylist(planted), [1])
    assert not bad.agrees and bad.worst_index == "ise_theta"
    assert bad.worst_relative == pytest.approx(1e-4, rel=1e-3)
    assert "**differs**" in full_stack.markdown([good, bad], 1e-6)


def test_runs_are_spread_and_wire_off_is_refused(tmp_path):
    assert full_stack.pick_runs(100, 3) == [0, 50, 99] and full_stack.pick_runs(5, 1) == [0]
    with pytest.raises(full_stack.FullStackRefused, match="allowed: 1..4"):
        full_stack.pick_runs(4, 5)
    spec = replace(load_campaign(specs.write(tmp_path, specs.BOX, "box", duration=1.0)), wire_float32=False)
    assert "wire_float32 = true" in full_stack.refusal(spec)

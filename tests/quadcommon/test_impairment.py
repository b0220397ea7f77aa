"""The link impairment model (quadcommon/impairment.py): seeded, deterministic, time as an argument;
the spec syntax and its errors; the [impair] table of sitl.toml."""

import pytest

from quadcommon.config import load_sitl
from quadcommon.impairment import (
    REORDER_HOLD_S,
    ImpairConfig,
    ImpairedChannel,
    Impairment,
    ImpairmentError,
    channel_seed,
    parse_impairment,
    parse_link_spec,
)
from quadcommon.schema import ConfigError

N = 20_000


def _send_all(channel: ImpairedChannel, n: int = N, period: float = 0.002) -> list[tuple[float, int]]:
    """Send datagrams 0..n-1 every ``period`` s; (arrival time, index) of every copy, in order."""
    arrivals = []
    for k in range(n):
        now = k * period
        for item in channel.due(now):
            arrivals.append((now, item))
        channel.send(k, now)
        for item in channel.due(now):
            arrivals.append((now, item))
    end = n * period + 20.0
    arrivals += [(end, item) for item in channel.due(end)]
    return arrivals


def test_the_spec_parses_with_units_and_describes_itself_back():
    imp = parse_impairment("loss=5%, delay=50ms,jitter=20ms,dup=1%,reorder=0.5%")
    assert imp == Impairment(loss=0.05, delay_s=0.05, jitter_s=0.02, duplicate=0.01, reorder=0.005)
    assert parse_impairment(imp.describe()) == imp
    assert parse_impairment("delay=1.5s").delay_s == 1.5
    assert parse_impairment("jitter=250us").jitter_s == pytest.approx(250e-6)
    assert parse_impairment("") == parse_impairment("none") == Impairment()
    assert not Impairment().active and Impairment(reorder=0.01).active
    assert parse_link_spec("gcs:loss=5%") == ("gcs", Impairment(loss=0.05))


@pytest.mark.parametrize(
    "spec, message",
    [
        ("hil:loss=101%", "--impair hil: loss=101% is out of range; allowed: 0 % to 100 %"),
        ("hil:loss=-1%", "--impair hil: loss=-1% is out of range; allowed: 0 % to 100 %"),
        ("gcs:loss=5", "--impair gcs: loss=5: give a percentage with '%', e.g. loss=1%"),
        ("gcs:delay=50", "--impair gcs: delay=50: give a time with its unit (ms, us or s), e.g. delay=50ms"),
        ("api:jitter=11s", "--impair api: jitter=11s is out of range; allowed: 0 ms to 10000 ms"),
        ("api:dup=nan%", "--impair api: dup=nan% is not a number"),
        ("api:drop=5%", "--impair api: unknown key 'drop'; known: loss, dup, reorder, delay, jitter"),
        ("api:loss", "--impair api: 'loss' is not KEY=VALUE (e.g. loss=5%)"),
        ("wifi:loss=5%", "--impair 'wifi:loss=5%': give LINK:SPEC with LINK one of hil, gcs, api"),
        ("loss=5%", "--impair 'loss=5%': give LINK:SPEC with LINK one of hil, gcs, api"),
    ],
)
def test_a_bad_spec_is_refused_naming_the_value_its_unit_and_range(spec, message):
    with pytest.raises(ImpairmentError) as info:
        ImpairConfig().with_specs([spec])
    assert message in str(info.value)
    assert isinstance(info.value, ConfigError)  # the command lines report it as a configuration error


def test_specs_are_repeatable_and_a_later_one_wins():
    config = ImpairConfig(seed=4).with_specs(["hil:loss=1%", "gcs:delay=50ms", "hil:dup=2%"])
    assert config.hil == Impairment(duplicate=0.02) and config.gcs == Impairment(delay_s=0.05)
    assert config.api == Impairment() and config.seed == 4
    assert config.channel("api", "in") is None  # a perfect link: the direct path
    assert config.describe() == "hil: dup=2%; gcs: delay=50ms"


def test_the_impair_table_is_read_and_validated_naming_file_and_key(tmp_path):
    path = tmp_path / "sitl.toml"
    path.write_text('[impair]\nseed = 7\nhil = "loss=1%"\ngcs = "delay=50ms,jitter=20ms"\n')
    config = load_sitl(path).impair
    assert config == ImpairConfig(7, Impairment(loss=0.01), Impairment(delay_s=0.05, jitter_s=0.02))
    path.write_text('[impair]\napi = "loss=150%"\n')
    with pytest.raises(ConfigError, match=r"sitl.toml: key 'impair.api' = 'loss=150%': loss=150% is out of "
                       r"range; allowed: 0 % to 100 %"):  # fmt: skip
        load_sitl(path)
    path.write_text('[impair]\nwifi = "loss=1%"\n')
    with pytest.raises(ConfigError, match="wifi"):
        load_sitl(path)
    path.write_text("[lockstep]\ntimeout_s = 0.1\nresend_s = 0.2\n")
    with pytest.raises(ConfigError, match=r"'lockstep.resend_s' = 0.2 is invalid; allowed: less than"):
        load_sitl(path)
    assert load_sitl().impair == ImpairConfig()  # the shipped file: perfect links


def test_the_same_seed_gives_the_same_fates_and_another_seed_others():
    imp = Impairment(loss=0.05, delay_s=0.01, jitter_s=0.005, duplicate=0.02, reorder=0.02)
    a = _send_all(ImpairedChannel(imp, 1))
    assert a == _send_all(ImpairedChannel(imp, 1))
    assert a != _send_all(ImpairedChannel(imp, 2))
    assert channel_seed(0, "hil sim->ap") != channel_seed(0, "hil ap->sim") != channel_seed(1, "hil sim->ap")


def test_loss_and_duplication_happen_at_their_rates():
    channel = ImpairedChannel(Impairment(loss=0.05, duplicate=0.01), 11)
    arrivals = _send_all(channel)
    c = channel.counts
    assert c.sent == N and c.delivered == len(arrivals) == N - c.dropped + c.duplicated
    assert 0.045 * N < c.dropped < 0.055 * N  # binomial: 5 % +- 3.5 sigma
    assert 0.0075 * N < c.duplicated < 0.0125 * N
    indices = [k for _, k in arrivals]
    assert len(set(indices)) == N - c.dropped  # each copy of a datagram is that datagram
    assert indices == sorted(indices)  # without delay nothing is reordered: both copies at once


def test_delay_and_jitter_bound_each_arrival_and_jitter_alone_may_reorder():
    channel = ImpairedChannel(Impairment(delay_s=0.05, jitter_s=0.02), 5)
    period = 0.002
    arrivals = []
    for k in range(2000):  # the arrival time of each copy, read when asked exactly then
        channel.send(k, k * period)
    while (due := channel.next_due()) is not None:
        arrivals += [(due, k) for k in channel.due(due)]
    latency = [t - k * period for t, k in arrivals]
    assert min(latency) >= 0.03 - 1e-12 and max(latency) <= 0.07 + 1e-12
    assert max(latency) - min(latency) > 0.035  # spread over the +-20 ms
    order = [k for _, k in arrivals]
    assert order != sorted(order) and sorted(order) == list(range(2000))  # netem's jitter reorders
    assert channel.counts.delayed == 2000


def test_a_reordered_datagram_is_overtaken_by_those_sent_after_it():
    channel = ImpairedChannel(Impairment(reorder=0.1), 9)
    arrivals = _send_all(channel, 5000)
    held = channel.counts.reordered
    assert 0.08 * 5000 < held < 0.12 * 5000
    order = [k for _, k in arrivals]
    overtaken = {k for i, k in enumerate(order) if any(j > k for j in order[:i])}
    assert len(overtaken) == held  # every held datagram arrives after some sent later ...
    in_time = [k for k in order if k not in overtaken]
    assert in_time == sorted(in_time)  # ... and the others keep their order
    for t, k in arrivals:
        assert t - k * 0.002 <= REORDER_HOLD_S + 0.002 + 1e-12


def test_time_is_an_argument_and_nothing_leaves_before_its_time():
    channel = ImpairedChannel(Impairment(delay_s=0.1), 0)
    channel.send(b"x", 10.0)
    assert channel.due(10.099) == [] and channel.next_due() == pytest.approx(10.1)
    assert channel.due(10.1) == [b"x"] and channel.next_due() is None
    channel.set(Impairment(loss=1.0))  # changed while running: from now on
    channel.send(b"y", 11.0)
    assert channel.due(100.0) == [] and channel.counts.dropped == 1
    assert channel.info()["impairment"] == "loss=100%"


def test_quadsitl_impair_refuses_a_bad_spec_before_sending_anything(capsys):
    from gcs_scripts import impair

    assert impair.main(["api:loss=5"], prog="quadsitl impair") == 2
    assert "quadsitl impair: impair api: loss=5: give a percentage with '%'" in capsys.readouterr().err


def test_a_live_change_applies_to_the_links_it_names_and_reports_them():
    from quadcommon.impaired_udp import ImpairedLinks

    links = ImpairedLinks(ImpairConfig().with_specs(["hil:loss=1%"]), "autopilot")
    links.receiver("api", "in")
    hil = links.sender(None, "hil", "ap->sim")
    assert links.receiver("gcs", "in").channel is None  # perfect: no channel, the direct path
    ok, reply = links.change(b"api:loss=100% hil:none")
    assert ok and hil.channel.impairment == Impairment() and links.endpoints[("api", "in")].channel
    assert '"api in": {"impairment": "loss=100%"' in reply.decode()
    ok, reply = links.change(b"api:loss=500%")
    assert not ok and "loss=500% is out of range" in reply.decode() and links.config.api.loss == 1.0


def test_endpoints_are_active_once_a_link_has_a_channel_at_start_or_by_a_live_change():
    """What a shell's loop asks every frame (flush the held datagrams?) follows the channels."""
    from quadcommon.impaired_udp import ImpairedLinks

    perfect = ImpairedLinks(ImpairConfig(), "in-process")
    perfect.receiver("gcs", "in")
    perfect.receiver("api", "out")
    assert not perfect.endpoints_active
    ok, _ = perfect.change(b"gcs:delay=20ms")
    assert ok and perfect.endpoints_active
    impaired = ImpairedLinks(ImpairConfig().with_specs(["hil:loss=1%"]), "simulator")
    impaired.receiver("gcs", "in")
    assert not impaired.endpoints_active
    impaired.receiver("hil", "sim->ap")
    assert impaired.endpoints_active

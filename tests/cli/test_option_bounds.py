"""Per-option bounds (viform.cli._types.OPTION_BOUNDS) and the light-link work check.

Absurd values that used to run for minutes (found by the option fuzz campaign) are refused
before any work: exit 2, one line naming the flag, saying what is allowed and why. The
simulations are replaced by stubs that fail the test if reached, so a missing bound fails
at once instead of running for minutes.
"""

import pytest

import viform.cli.display as display_cli
from viform.cli import main


@pytest.fixture
def no_work(monkeypatch):
    """The commands' simulations: reaching one means the request was not refused up front."""
    calls = []

    def stub(name):
        def run(*args, **kwargs):
            calls.append((name, args))
            raise AssertionError(f"{name} ran")
        return run

    monkeypatch.setattr(display_cli, "run_lightcomm", stub("lightcomm"))
    monkeypatch.setattr(display_cli, "run_display", stub("display"))
    return calls


@pytest.mark.parametrize("args, flag, allowed", [
    (["lightcomm", "--bitrate", "1e-300"], "--bitrate", "use at least 16 bit/s"),  # 400 bits × 40 kHz / 10⁶ ticks
    (["lightcomm", "--bits", "2147483648"], "--bits", "[1, 1e+06] bits"),
    (["lightcomm", "--clock-hz", "2147483648"], "--clock-hz", "[1, 1e+08] Hz"),
    (["display", "--eye-ms", "2147483648"], "--eye-ms", "[0.025, 200] ms"),
    (["display", "--eye-ms", "0.001"], "--eye-ms", "[0.025, 200] ms"),  # under one tick: no eye window
    (["lightcomm", "--clock-hz", "1e8"], "--bitrate", "use at least 4e+04 bit/s"),  # 400 × 1e8 / 10⁶
    (["lightcomm", "--message", "hi", "--bitrate", "0.5"], "--message", "16 bits"),
    (["lightcomm", "--bitrate", "20", "--sweeps"], "--sweeps", "leave the sweeps out"),
])
def test_absurd_values_refused_before_work(no_work, capsys, args, flag, allowed):
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and flag in err and allowed in err, err
    assert no_work == []


@pytest.mark.parametrize("args", [
    ["lightcomm", "--bitrate", "16"],  # exactly 10⁶ ticks
    ["lightcomm", "--bits", "1000000", "--bitrate", "40000"],
    ["lightcomm", "--clock-hz", "1e8", "--bitrate", "1e5", "--bits", "10"],
    ["display", "--eye-ms", "200"],
    ["display", "--eye-ms", "0.025"],
])
def test_values_at_the_bounds_are_accepted(no_work, capsys, args):
    main(args)  # the stub's AssertionError becomes main's one-line internal error
    assert [name for name, _ in no_work] == [args[0]]

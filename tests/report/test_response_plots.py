"""response.png of a compressive pixel: the overflow segments that look flat on log–log axes
get a panel that shows them rising, with the slopes the seed's equations give."""

import numpy as np

from viform.report.response_plots import response_figure
from viform.sensors import catalog


def _noise_free_curve(sensor, lux):
    """The seed 003 pixel's output from eqs. 1–6 (no noise), normalised as characterize does."""
    sig = sensor.expected_signal_electrons(sensor.photocurrent_a(lux))
    return {"lux": lux, "output": sig / sig.max(), "snr": np.full(lux.size, 1e3)}


def test_overflow_knee_panel_slopes_match_the_equations(check_layout):
    """Between C (photodiode saturated within t1) and D (saturated within t2) only t2, diluted by
    the sharing onto C_F, and t3 add signal: slope / slope(A→B) = (t2·C_PD/(C_PD + C_F) + t3) / T
    (seed 003 eqs. 4–6), 1/316 for the seed's pixel; D→E: t3 / T = 1/1111. The panel prints
    these (to the 2 % a 2000-point curve interpolated at the knees allows)."""
    s = catalog.make_sensor("seed003-overflow", height=16, width=16)
    lux = np.geomspace(1e-3, 1e5, 2000)
    knees = {f"{k} knee": float(s.lux_from_photocurrent(v)) for k, v in s.segment_boundaries_a().items()
             if k in "BCDE"}
    fig = response_figure({"overflow": _noise_free_curve(s, lux)}, "t", highlight="overflow", knees_lux=knees)
    assert len(fig.axes) == 3
    notes = [t.get_text() for t in fig.axes[2].texts if t.get_text().startswith("slope")]
    ratios = [float(n.split("/")[-1]) for n in notes if "/" in n]
    t1, t2, t3 = s.integration_times_s
    share = s.c_pd_f / (s.c_pd_f + s.overflow_capacitance_f)
    expected = [(t1 + t2 + t3) / (t2 * share + t3), (t1 + t2 + t3) / t3]
    assert len(ratios) == 2
    assert np.allclose(ratios, expected, rtol=0.02), (ratios, expected)
    assert [t.get_text() for t in fig.axes[2].texts if len(t.get_text()) == 1] == ["B", "C", "D", "E"]
    check_layout(fig)


def test_no_knees_keeps_two_panels():
    lux = np.geomspace(0.1, 1e3, 50)
    c = {"lux": lux, "output": np.minimum(lux / 500, 1), "snr": np.full(50, 100.0)}
    fig = response_figure({"a": c}, "t", highlight="a")
    assert len(fig.axes) == 2
    import matplotlib.pyplot as plt

    plt.close(fig)

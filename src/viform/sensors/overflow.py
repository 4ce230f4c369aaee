"""Conditional-overflow multi-integration pixel with a column-shared capacitor (seed 003).

Each frame period (33.33 ms at 30 fps) holds three integrations: long t1 = 32.8 ms,
medium t2 = 0.5 ms, short t3 = 0.03 ms (seed 003, §3). The photodiode is reset to
V_res (the PMOS reset PM1 pulls it to VCC = 3.3 V) and discharges as
``V = V_i0 − (I_ph + I_dark)·t / C_PD``, floored at the saturation voltage V_sat
(seed 003, eq. 3). At the end of t1 and of t2 the row borrows its column's shared unit:
the overflow capacitor C_F (500 fF) is reset to VF = 2.2 V and compared with the
photodiode; if V_PD < V_CF they share charge (seed 003, eq. 1)::

    V'_PD = V_PD                                     if V_PD > V_CF
    V'_PD = (V_PD·C_PD + V_CF·C_F) / (C_F + C_PD)    if V_PD < V_CF

which sets the start of the next integration (eqs. 4–6: V10 = V_res,
V20 = (V1·C_PD + V_CF·C_F)/(C_F + C_PD), V30 = (V2·C_PD + V_CF·C_F)/(C_F + C_PD)).
After t3 the pixel is read with correlated double sampling: signal = V_res − V3
(the reset sample removes the pixel offset, seed 003 §3).

The resulting output-vs-photocurrent curve has four parts (seed 003, §6, fig. 6):
AB no overflow (identical to a plain 4T APS integrating the whole frame), BC overflow
without saturation, CD saturated at the end of t1 only, DE saturated at the end of t1
and t2; the curve ends where the photodiode saturates inside t3.

Column-shared unit timing (seed 003, §5): each row holds its column's unit from the end
of t1 to the end of t2, i.e. t2 plus two uses of < 0.01 ms each ≈ 0.51 ms; rows take
turns, so rows × 0.51 ms must fit in the frame period. Rows are staggered by
frame period / rows (row-by-row exposure, seed 003 §2).

Dynamic-range gain over the plain 4T APS (seed 003, §6 claims ≈ 62 dB = 20·lg(10 nA / 8 pA)).
Both pixels share the low end (segment AB is the 4T response), so the gain is the ratio of
the largest usable photocurrents. The 4T (same photodiode, whole frame T = t1 + t2 + t3)
saturates at I_4T = (V_res − V_sat)·C_PD/T. The overflow pixel's curve ends at E, where the
photodiode saturates within t3 after the second sharing; in segment DE, V1 = V2 = V_sat and
C_F is reset to VF before each use, so eqs. 5–6 give V30 = V20 = (V_sat·C_PD + VF·C_F)/(C_F + C_PD)
and E = (V30 − V_sat)·C_PD/t3. The charge moved onto C_F is never read (only V_PD is), so
C_F does not add to the well that t3 fills. Hence (:func:`dynamic_range_gain_db`)::

    E / I_4T = (T / t3) · (VF − V_sat)/(V_res − V_sat) · C_F/(C_F + C_PD)
             < (T / t3) · VF / V_res = 1111 × 2.2/3.3 = 741   (57.4 dB, any C_PD, C_F, V_sat ≥ 0)

With the calibrated C_PD = 88.9 fF and V_sat = 0.3 V this is 55.5 dB (E = 4.78 nA). The
seed's own figures say the same: eqs. 5–6 make D (saturation within t2) and E share the
starting voltage V20, so E/D = t2/t3 = 16.7, and the seed's D = 270 pA gives E = 4.5 nA
(55.0 dB), not 10 nA (10 nA / 270 pA = 37). 62 dB would need 1250 > T/t3 = 1111, i.e. more
swing in t3 than the 4T has in the whole frame, or t3 ≈ 14 µs instead of the seed's 30 µs.

Noise model: Poisson photo + dark charge per integration window (exact at small counts),
PRNU/DSNU, read noise and ADC from :class:`~viform.sensors.frame.FramePixelArray`.
Charge is tracked as the photodiode voltage drop in electrons, ``n = (V_res − V)·C_PD/q``,
so the pixel's full well is ``(V_res − V_sat)·C_PD/q`` and its conversion gain q/C_PD.
Reset (kTC) noise, optional (``ktc_noise=True``): the seed's readout samples the
signal *before* resetting the photodiode and the reset level after it (§3: "read the signal
… then PM1 and NM3 reset the photodiode, read the reset noise"), so the two samples carry
the kTC noise of two different resets and it does not cancel: √(kT·C_PD)/q = 120 e⁻ rms per
reset at 88.9 fF and 300 K, √2 × 120 = 170 e⁻ in the difference. Each conditional sharing
adds the kTC noise of C_F's reset to VF, scaled by C_F/(C_F + C_PD) onto the photodiode, and
the partition noise of opening the switch, kT·C_PD·C_F/(C_PD + C_F):
√(44² + 110²) = 118 e⁻ at the photodiode (:func:`share_ktc_noise_electrons`).

The seed's PGA (§2: CDS → PGA → ADC) is the pixel's ``analog_gain`` (``pga_gain``).

:func:`lofic_pixel_parameters` is the lateral-overflow-integration-capacitor pixel the seed
compares against (Fig. 5(b), DR_b = 20·lg(E4/E2)): the photodiode and an in-pixel C_S
integrate together and are read at the low conversion gain q/(C_PD + C_S), so the well is
(C_PD + C_S)/C_PD times larger but the input-referred read and kTC noise grow too — the
poorer low-light sensitivity and SNR the seed describes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError, check_int, check_non_negative, check_positive, check_range
from viform.light.radiometry import ELEMENTARY_CHARGE_C
from viform.light.scenes import Scene, StillScene
from viform.sensors.frame import FramePixelParameters, FrameSensor

#: Boltzmann constant, J/K.
BOLTZMANN_J_PER_K = 1.380649e-23


def ktc_noise_electrons(capacitance_f: float, temperature_k: float = 300.0) -> float:
    """Reset (kTC) noise of a node, electrons rms: √(k·T·C)/q (≈ 120 e⁻ at 88.9 fF, 300 K)."""
    check_positive("capacitance_f", capacitance_f)
    check_positive("temperature_k", temperature_k)
    return float(np.sqrt(BOLTZMANN_J_PER_K * temperature_k * capacitance_f) / ELEMENTARY_CHARGE_C)


def share_ktc_noise_electrons(c_pd_f: float, c_f_f: float, temperature_k: float = 300.0) -> float:
    """Noise one conditional sharing adds at the photodiode, electrons rms (seed 003, eq. 1).

    C_F is reset to VF with kTC noise √(kT/C_F) in volts; sharing puts C_F/(C_F + C_PD) of
    it on the photodiode: √(kT·C_F)/q · C_PD/(C_F + C_PD) electrons. Opening the switch
    then partitions the thermal charge of the pair: variance kT·C_PD·C_F/(C_PD + C_F)/q².
    """
    from_cf = ktc_noise_electrons(c_f_f, temperature_k) * c_pd_f / (c_f_f + c_pd_f)
    partition = ktc_noise_electrons(c_pd_f * c_f_f / (c_pd_f + c_f_f), temperature_k)
    return float(np.hypot(from_cf, partition))


#: Seed 003 §3 integration times: long, medium, short (s), in a 33.33 ms frame.
PAPER003_INTEGRATIONS_S = (32.8e-3, 0.5e-3, 0.03e-3)


@dataclass(frozen=True)
class OverflowCircuit:
    """The conditional-overflow pixel's circuit values (seed 003, §3 and Table 1), in one place.

    Attributes
    ----------
    c_f_f : float
        Column-shared overflow capacitance C_F, farads.
    v_reset_v : float
        Photodiode reset voltage V_res, volts.
    v_f_v : float
        Overflow (sharing) decision level V_F, volts.
    v_sat_v : float
        Photodiode saturation voltage V_sat, volts.
    integration_times_s : tuple of float
        The three integrations t1, t2, t3, seconds.
    """

    c_f_f: float = 500e-15
    v_reset_v: float = 3.3
    v_f_v: float = 2.2
    v_sat_v: float = 0.3
    integration_times_s: tuple = PAPER003_INTEGRATIONS_S


#: The paper's circuit: the default of every function and sensor of this module.
PAPER003_CIRCUIT = OverflowCircuit()
_C = PAPER003_CIRCUIT


def share_charge_v(v_pd_v, v_cf_v: float, c_pd_f: float, c_f_f: float):
    """Photodiode voltage after the conditional overflow (seed 003, eq. 1).

    >>> round(float(share_charge_v(0.3, 2.2, 100e-15, 500e-15)), 4)
    1.8833
    >>> float(share_charge_v(2.5, 2.2, 100e-15, 500e-15))
    2.5
    """
    v = np.asarray(v_pd_v, dtype=np.float64)
    shared = (v * c_pd_f + v_cf_v * c_f_f) / (c_f_f + c_pd_f)
    return np.where(v < v_cf_v, shared, v)


class PhotodiodeJunction:
    """The photodiode's charge–voltage law, linear or a reverse-biased junction.

    A junction's capacitance grows as its reverse bias falls, C(V) = C_res·((1 + V_res/φ)/(1 + V/φ))^m
    (m = 0.5 abrupt, 1/3 linearly graded; φ the built-in potential), equal to C_res at the reset
    voltage. The charge removed from reset down to V is then, in closed form,

        Q(V) = C_res·(1 + V_res/φ)^m · φ/(1 − m) · [(1 + V_res/φ)^{1−m} − (1 + V/φ)^{1−m}]

    and m = 0 gives the linear C_res·(V_res − V). The well to a given V_sat holds more charge
    than the linear law says, and the gain q/C(V) falls as the photodiode discharges.
    """

    def __init__(self, c_reset_f: float, v_reset_v: float, grading_m: float = 0.0, built_in_v: float = 0.7):
        self.c_reset_f = check_positive("c_reset_f", c_reset_f)
        self.v_reset_v = float(v_reset_v)
        self.grading_m = check_range("junction_grading_m", grading_m, 0.0, 0.9)
        self.built_in_v = check_positive("junction_built_in_v", built_in_v)
        m, phi = self.grading_m, self.built_in_v
        self._k = self.c_reset_f * (1 + self.v_reset_v / phi) ** m * phi / (1 - m)
        self._top = (1 + self.v_reset_v / phi) ** (1 - m)

    @property
    def linear(self) -> bool:
        return self.grading_m == 0

    def capacitance_f(self, v_v):
        """C(V), F."""
        v = np.asarray(v_v, dtype=np.float64)
        return self.c_reset_f * ((1 + self.v_reset_v / self.built_in_v) / (1 + v / self.built_in_v)) ** self.grading_m

    def discharge_c(self, v_v):
        """Charge removed from reset to reach V, C."""
        v = np.asarray(v_v, dtype=np.float64)
        if self.linear:
            return self.c_reset_f * (self.v_reset_v - v)
        return self._k * (self._top - (1 + v / self.built_in_v) ** (1 - self.grading_m))

    def voltage_v(self, q_c):
        """Photodiode voltage after removing charge ``q_c`` from reset, V."""
        q = np.asarray(q_c, dtype=np.float64)
        if self.linear:
            return self.v_reset_v - q / self.c_reset_f
        base = np.maximum(self._top - q / self._k, 0.0)
        return self.built_in_v * (base ** (1 / (1 - self.grading_m)) - 1)

    def share_v(self, v_v, v_f_v: float, c_f_f):
        """Eq. 1 with this junction: V' with Q(V') + C_F·(VF − V') = Q(V) (charge conserved), for
        V < VF; the linear law gives (V·C_PD + VF·C_F)/(C_F + C_PD)."""
        v = np.asarray(v_v, dtype=np.float64)
        c_f = np.asarray(c_f_f, dtype=np.float64)
        if self.linear:
            return (v * self.c_reset_f + v_f_v * c_f) / (c_f + self.c_reset_f)
        target = self.discharge_c(v)
        lo, hi = np.minimum(v, v_f_v), np.full(np.broadcast(v, c_f).shape, float(v_f_v))
        lo = np.broadcast_to(lo, hi.shape).copy()
        for _ in range(60):  # f(V') = Q(V') + C_F (VF − V') − Q(V) falls from > 0 at V to < 0 at VF
            mid = 0.5 * (lo + hi)
            f = self.discharge_c(mid) + c_f * (v_f_v - mid) - target
            lo, hi = np.where(f > 0, mid, lo), np.where(f > 0, hi, mid)
        return 0.5 * (lo + hi)


def junction_segment_boundaries_a(junction: PhotodiodeJunction, c_f_f: float = _C.c_f_f, v_f_v: float = _C.v_f_v,
                                  v_sat_v: float = _C.v_sat_v, integration_times_s=_C.integration_times_s) -> dict:
    """Points B, C, D, E (A) for any junction law: B = Q(VF)/(t1 + t2), C = Q(V_sat)/t1,
    D and E = (Q(V_sat) − Q(V20))/t2 and /t3 with V20 the sharing of V_sat (eq. 1); the 4T's
    saturation I_4T = Q(V_sat)/T. Equal to :func:`segment_boundaries_a` for a linear junction."""
    t1, t2, t3 = integration_times_s
    q = junction.discharge_c
    v20 = float(junction.share_v(v_sat_v, v_f_v, c_f_f))
    swing = float(q(v_sat_v) - q(v20))
    return {"B": float(q(v_f_v)) / (t1 + t2), "C": float(q(v_sat_v)) / t1, "D": swing / t2, "E": swing / t3,
            "v20_after_saturation_v": v20, "I_4T": float(q(v_sat_v)) / sum(integration_times_s)}


def overflow_voltages_v(
    photocurrent_a,
    c_pd_f: float,
    c_f_f: float = _C.c_f_f,
    v_reset_v: float = _C.v_reset_v,
    v_f_v: float = _C.v_f_v,
    v_sat_v: float = _C.v_sat_v,
    integration_times_s=_C.integration_times_s,
    dark_current_a: float = 0.0,
):
    """Noise-free photodiode voltages (V1, V2, V3) at the end of t1, t2, t3 (seed 003, eqs. 1–6).

    V1, V2 are before the charge sharing; the next integration starts from eq. 1's V'.
    """
    i = np.asarray(photocurrent_a, dtype=np.float64) + dark_current_a
    t1, t2, t3 = integration_times_s
    v1 = np.maximum(v_reset_v - i * t1 / c_pd_f, v_sat_v)  # eq. 3 from V10 = V_res (eq. 4)
    v20 = share_charge_v(v1, v_f_v, c_pd_f, c_f_f)  # eq. 5
    v2 = np.maximum(v20 - i * t2 / c_pd_f, v_sat_v)
    v30 = share_charge_v(v2, v_f_v, c_pd_f, c_f_f)  # eq. 6
    v3 = np.maximum(v30 - i * t3 / c_pd_f, v_sat_v)
    return v1, v2, v3


def segment_boundaries_a(
    c_pd_f: float,
    c_f_f: float = _C.c_f_f,
    v_reset_v: float = _C.v_reset_v,
    v_f_v: float = _C.v_f_v,
    v_sat_v: float = _C.v_sat_v,
    integration_times_s=_C.integration_times_s,
) -> dict:
    """Photocurrents (A) at the seed's points B, C, D, E (seed 003, §6, fig. 6), from eqs. 1–6.

    B: first overflow (V_PD reaches V_F by the end of t1 + t2 — the later check, since the
    photodiode keeps discharging through t2); C: saturation within t1; D: saturation within
    t2 after the first sharing; E: saturation within t3 after the second sharing.
    """
    t1, t2, t3 = integration_times_s
    b = (v_reset_v - v_f_v) * c_pd_f / (t1 + t2)
    c = (v_reset_v - v_sat_v) * c_pd_f / t1
    v20_sat = float(share_charge_v(v_sat_v, v_f_v, c_pd_f, c_f_f))
    d = (v20_sat - v_sat_v) * c_pd_f / t2
    e = (v20_sat - v_sat_v) * c_pd_f / t3
    return {"B": b, "C": c, "D": d, "E": e, "v20_after_saturation_v": v20_sat}


def dynamic_range_gain_db(
    c_pd_f: float,
    c_f_f: float = _C.c_f_f,
    v_reset_v: float = _C.v_reset_v,
    v_f_v: float = _C.v_f_v,
    v_sat_v: float = _C.v_sat_v,
    integration_times_s=_C.integration_times_s,
) -> float:
    """Noise-free DR gain over the plain 4T APS, 20·lg(E / I_4T), dB (seed 003, §6, eqs. 3–6).

    I_4T = (V_res − V_sat)·C_PD/(t1 + t2 + t3) is where the 4T (same photodiode, whole
    frame) saturates; E is :func:`segment_boundaries_a`'s end of segment DE. The low ends
    coincide (segment AB), so this ratio is the gain. In closed form
    ``(T/t3)·(VF − V_sat)/(V_res − V_sat)·C_F/(C_F + C_PD)``, below ``20·lg((T/t3)·VF/V_res)``.

    >>> round(dynamic_range_gain_db(8e-12 * 33.33e-3 / 3.0), 2)
    55.53
    """
    times = tuple(integration_times_s)
    e = segment_boundaries_a(c_pd_f, c_f_f, v_reset_v, v_f_v, v_sat_v, times)["E"]
    i_4t = (v_reset_v - v_sat_v) * c_pd_f / sum(times)
    return float(20 * np.log10(e / i_4t))


class OverflowSensor(FrameSensor):
    """Conditional-overflow, triple-integration HDR camera (seed 003).

    Parameters
    ----------
    parameters : FramePixelParameters
        The pixel. Its conversion gain gives C_PD = q / CG, and its full well the
        photodiode swing V_res − V_sat = FW · CG.
    integration_times_s : (t1, t2, t3)
        Long, medium, short integrations, s (seed 003: 32.8 ms, 0.5 ms, 0.03 ms).
    overflow_capacitance_f : float
        Column-shared capacitor C_F, F (seed 003: 500 fF).
    v_f_v : float
        Reset voltage of C_F, V (seed 003: VF = 2.2 V).
    v_reset_v : float
        Photodiode reset voltage, V (seed 003: VCC = 3.3 V).
    share_use_time_s : float
        Duration of one use of the column unit (reset + compare + share), s (< 0.01 ms).
    frame_rate_hz : float
        Frames per second (seed 003: 30).
    height, width, noise, fixed_pattern_seed
        As :class:`~viform.sensors.frame.FrameSensor`.
    ktc_noise : bool
        Add the reset noise as the seed's readout samples it (see the module notes). Default
        False (the seed's own analysis ignores it).
    temperature_k : float
        Temperature of the kTC noise, K.
    comparator_offset_v : float
        Column-to-column spread (std, V) of the overflow comparator's offset: column c shares
        when V_PD < VF + δ_c (fixed pattern, seeded by ``fixed_pattern_seed``). Default 0.
        A positive δ_c makes a photodiode slightly *above* VF share, pulling it down towards VF
        by (V_PD − VF)·C_F/(C_F + C_PD): a kink in the response whose place varies by column.
    comparator_noise_v : float
        Temporal noise (std, V) of each overflow decision: a decision within a few σ of the
        threshold flips at random, P(share) = Φ((VF + δ_c − V_PD)/σ). Default 0.
    overflow_capacitance_spread : float
        Column-to-column relative spread (std / mean) of C_F (fixed pattern): the sharing
        ratio, and so the response above the first overflow, varies by column (column FPN).
        Default 0.
    charge_injection_electrons : float
        Charge the share switch injects into the photodiode when it opens, e⁻ of discharge
        per sharing (signed; half the channel charge of a minimum switch is a few hundred e⁻
        at 0.35 µm). Default 0.
    column_bus_capacitance_f : float
        Capacitance of the column bus that connects the column-shared C_F to the pixel, F;
        it is reset to VF with C_F and shares with it, so C_F acts as C_F + C_bus. Default 0
        (a 32-row column of 0.35 µm metal is ≈ 50–100 fF).
    junction_grading_m, junction_built_in_v : float
        The photodiode's capacitance–voltage law (:class:`PhotodiodeJunction`): C_PD is the
        value at the reset voltage and grows as the photodiode discharges. Default m = 0 (the
        seed's linear C_PD); an abrupt junction has m = 0.5, φ ≈ 0.7 V. The output is the CDS
        voltage V_res − V3, reported in electrons of the nominal gain q/C_PD.
    """

    name = "overflow"

    def __init__(
        self,
        parameters: FramePixelParameters | None = None,
        integration_times_s=_C.integration_times_s,
        overflow_capacitance_f: float = _C.c_f_f,
        v_f_v: float = _C.v_f_v,
        v_reset_v: float = _C.v_reset_v,
        share_use_time_s: float = 5e-6,
        frame_rate_hz: float = 30.0,
        height: int | None = None,
        width: int | None = None,
        noise: bool = True,
        fixed_pattern_seed: int = 1288,
        ktc_noise: bool = False,
        temperature_k: float = 300.0,
        comparator_offset_v: float = 0.0,
        comparator_noise_v: float = 0.0,
        overflow_capacitance_spread: float = 0.0,
        charge_injection_electrons: float = 0.0,
        column_bus_capacitance_f: float = 0.0,
        junction_grading_m: float = 0.0,
        junction_built_in_v: float = 0.7,
    ):
        parameters = parameters or paper003_pixel_parameters()
        self.comparator_offset_v = check_non_negative("comparator_offset_v", comparator_offset_v)
        self.comparator_noise_v = check_non_negative("comparator_noise_v", comparator_noise_v)
        self.overflow_capacitance_spread = check_range("overflow_capacitance_spread", overflow_capacitance_spread,
                                                       0.0, 0.3)
        self.charge_injection_electrons = check_range("charge_injection_electrons", charge_injection_electrons,
                                                      -1e7, 1e7)
        self.column_bus_capacitance_f = check_non_negative("column_bus_capacitance_f", column_bus_capacitance_f)
        self._column_maps: dict = {}
        self.ktc_noise = bool(ktc_noise)
        self.temperature_k = check_positive("temperature_k", temperature_k)
        frame_rate_hz = check_positive("frame_rate_hz", frame_rate_hz)
        period = 1.0 / frame_rate_hz
        times = tuple(np.atleast_1d(np.asarray(integration_times_s, dtype=np.float64)).tolist())
        if len(times) != 3:
            raise ViformError(
                f"integration_times_s must give three durations (long, medium, short); "
                f"got {len(times)}"
            )
        for name, t in zip(("long", "medium", "short"), times, strict=True):
            check_positive(f"integration_times_s ({name})", t)
        if sum(times) > period * (1 + 1e-9):
            raise ViformError(
                f"integration_times_s sum to {sum(times) * 1e3:g} ms, which exceeds the "
                f"frame period {period * 1e3:g} ms at frame_rate_hz = {frame_rate_hz:g}"
            )
        self.integration_times_s = times
        self.overflow_capacitance_f = check_positive(
            "overflow_capacitance_f", overflow_capacitance_f
        )
        self.v_reset_v = check_positive("v_reset_v", v_reset_v)
        self.v_f_v = check_range("v_f_v", v_f_v, 0.0, self.v_reset_v, low_open=True, high_open=True)
        self.share_use_time_s = check_positive("share_use_time_s", share_use_time_s)
        self.c_pd_f = ELEMENTARY_CHARGE_C / parameters.conversion_gain_v_per_e
        self.junction = PhotodiodeJunction(self.c_pd_f, self.v_reset_v, junction_grading_m, junction_built_in_v)
        self.v_sat_v = (
            self.v_reset_v - parameters.full_well_electrons * parameters.conversion_gain_v_per_e
        )
        if self.v_sat_v < 0:
            raise ViformError(
                f"full_well_electrons × conversion_gain_v_per_e = "
                f"{self.v_reset_v - self.v_sat_v:g} V exceeds v_reset_v = {v_reset_v:g} V: the "
                f"photodiode would have to swing below 0 V (forward bias) to hold that charge"
            )
        if not self.v_sat_v < self.v_f_v:
            raise ViformError(
                f"the photodiode swing full_well_electrons × conversion_gain_v_per_e = "
                f"{self.v_reset_v - self.v_sat_v:g} V does not reach below v_f_v = {v_f_v:g} V "
                f"from v_reset_v = {v_reset_v:g} V; the overflow could never trigger"
            )
        super().__init__(
            parameters,
            exposure_s=sum(times),
            frame_rate_hz=frame_rate_hz,
            height=height,
            width=width,
            noise=noise,
            fixed_pattern_seed=fixed_pattern_seed,
        )
        if height is not None:
            self.check_row_timing(height)

    # ------------------------------------------------------------------ column-shared unit timing
    @property
    def row_share_time_s(self) -> float:
        """Time one row holds the column unit: t2 plus two uses (seed 003, §5: ≈ 0.51 ms)."""
        return self.integration_times_s[1] + 2 * self.share_use_time_s

    def max_rows(self) -> int:
        """Most rows whose turns at the column unit fit in one frame period (seed 003, §5)."""
        return int(np.floor((1.0 / self.frame_rate_hz) / self.row_share_time_s * (1 + 1e-12)))

    def check_row_timing(self, rows: int) -> None:
        """Refuse an array whose rows cannot all use the column-shared unit within a frame."""
        rows = check_int("height", rows, 1)
        need = rows * self.row_share_time_s
        period = 1.0 / self.frame_rate_hz
        if need > period * (1 + 1e-12):
            raise ViformError(
                f"height = {rows} rows do not fit the column-shared overflow unit: rows × "
                f"per-row use time = {rows} × {self.row_share_time_s * 1e3:.3f} ms = "
                f"{need * 1e3:.2f} ms exceeds the frame period {period * 1e3:.2f} ms "
                f"(seed 003 §5); at most {self.max_rows()} rows at "
                f"{self.frame_rate_hz:g} fps"
            )

    # ------------------------------------------------------------------ pixel physics
    @property
    def effective_overflow_capacitance_f(self) -> float:
        """C_F + the column bus that shares with it, F."""
        return self.overflow_capacitance_f + self.column_bus_capacitance_f

    def column_maps(self, width: int) -> tuple[np.ndarray, np.ndarray]:
        """Per-column comparator offset δ_c (V) and effective C_F (F), fixed pattern (W,) each."""
        if width not in self._column_maps:
            rng = np.random.default_rng([self.fixed_pattern_seed, 0xC0F])
            offset = self.comparator_offset_v * rng.standard_normal(width)
            c_f = self.effective_overflow_capacitance_f * np.clip(
                1.0 + self.overflow_capacitance_spread * rng.standard_normal(width), 0.05, None)
            self._column_maps[width] = (offset, c_f)
        return self._column_maps[width]

    def _share_electrons(self, n, c_f_f=None, decide=None):
        """Eq. 1 in electrons of photodiode discharge: n = (V_res − V)·C_PD/q.

        ``decide`` (bool array) overrides the ideal comparator V_PD < VF; ``c_f_f`` may be a
        per-column array. Sharing pixels also take the switch's injected charge."""
        c_f = self.effective_overflow_capacitance_f if c_f_f is None else c_f_f
        j = self.junction
        v = j.voltage_v(np.asarray(n, dtype=np.float64) * ELEMENTARY_CHARGE_C)
        share = v < self.v_f_v if decide is None else decide
        v = np.where(share, j.share_v(np.minimum(v, self.v_f_v), self.v_f_v, c_f), v)
        return j.discharge_c(v) / ELEMENTARY_CHARGE_C + np.where(share, self.charge_injection_electrons, 0.0)

    def share_decisions(self, n, rng: np.random.Generator | None, width: int) -> np.ndarray:
        """Which pixels the comparator lets share: V_PD < VF + δ_c (+ σ·N(0, 1) per decision)."""
        v = self.junction.voltage_v(np.asarray(n, dtype=np.float64) * ELEMENTARY_CHARGE_C)
        threshold = self.v_f_v + self.column_maps(width)[0]
        if self.comparator_noise_v > 0 and self.noise and rng is not None:
            threshold = threshold + self.comparator_noise_v * rng.standard_normal(np.shape(n))
        return v < threshold

    def capture_frame(
        self,
        scene: Scene,
        start_s: float,
        exposure_s: float | None = None,
        *,
        seed: int = 0,
        frame_index: int = 0,
    ) -> np.ndarray:
        """One frame: t1, share, t2, share, t3, CDS read (seed 003, §3).

        ``exposure_s`` scales the three integrations together (default: their seed sum).
        Row r starts r · (frame period / rows) after ``start_s`` (row-by-row exposure).
        """
        height, width = self.check_scene(scene, self.height, self.width)
        self.check_row_timing(height)
        pixels = self.pixel_array(height, width)
        rng = pixels.rng(seed, frame_index)
        scale = (
            1.0
            if exposure_s is None
            else check_positive("exposure_s", exposure_s) / self.exposure_s
        )
        times = [t * scale for t in self.integration_times_s]
        fw = self.well_electrons  # charge down to V_sat (the nominal full well if C_PD is linear)
        row_offset_s = (1.0 / self.frame_rate_hz) / height
        static = isinstance(scene, StillScene)
        n = np.zeros((height, width))
        ktc = self.ktc_noise and self.noise
        if ktc:  # the reset that starts the frame leaves kTC charge on C_PD
            n = n + self.reset_ktc_electrons * rng.standard_normal(n.shape)
        t0 = float(start_s)
        for k, t in enumerate(times):
            lux = self._window_lux(scene, t0, t, row_offset_s, static)
            n = np.minimum(
                n + pixels.collect_electrons(lux, t, rng, self.noise), fw
            )  # eq. 3, V ≥ V_sat
            if k < 2:
                shared = self.share_decisions(n, rng, width)
                n = self._share_electrons(n, self.column_maps(width)[1], shared)  # eqs. 1, 5, 6
                if ktc:  # C_F's reset noise and the switch's partition noise, where it shared
                    n = n + np.where(shared, self.share_ktc_electrons * rng.standard_normal(n.shape), 0.0)
            t0 += t
        if ktc:  # the reference sample is taken after a new, independent reset
            n = n - self.reset_ktc_electrons * rng.standard_normal(n.shape)
        # CDS: V_res − V3 is the signal; offsets cancel (seed 003, §3). It is read as a voltage:
        # in electrons of the nominal gain q/C_PD (the same as n for a linear photodiode).
        if not self.junction.linear:
            v3 = self.junction.voltage_v(n * ELEMENTARY_CHARGE_C)
            n = (self.v_reset_v - v3) / self.parameters.conversion_gain_v_per_e
        return pixels.digitize(n, rng, self.noise)

    @property
    def well_electrons(self) -> float:
        """Charge the photodiode holds from reset down to V_sat, e⁻ (= full_well_electrons when linear)."""
        if self.junction.linear:
            return self.parameters.full_well_electrons
        return float(self.junction.discharge_c(self.v_sat_v)) / ELEMENTARY_CHARGE_C

    @staticmethod
    def _window_lux(scene: Scene, t0: float, t: float, row_offset_s: float, static: bool):
        if static:
            return scene.mean_illuminance_lux(t0, t0 + t)
        return scene.rolling_mean_illuminance_lux(t0, t, row_offset_s)

    # ------------------------------------------------------------------ reset noise
    @property
    def reset_ktc_electrons(self) -> float:
        """kTC noise of one photodiode reset, e⁻ rms (≈ 120 e⁻ at 88.9 fF, 300 K)."""
        return ktc_noise_electrons(self.c_pd_f, self.temperature_k)

    @property
    def share_ktc_electrons(self) -> float:
        """Noise added at the photodiode by one conditional sharing, e⁻ rms."""
        return share_ktc_noise_electrons(self.c_pd_f, self.overflow_capacitance_f, self.temperature_k)

    def readout_reset_noise_electrons(self, shares: int = 0) -> float:
        """Reset noise in the output difference (signal sampled before the reset, reference
        after a new one): √2 × the per-reset kTC, plus ``shares`` sharings' noise, e⁻ rms."""
        return float(np.sqrt(2 * self.reset_ktc_electrons ** 2 + shares * self.share_ktc_electrons ** 2))

    # ------------------------------------------------------------------ analytic helpers
    def photocurrent_a(self, lux):
        """Photocurrent (A) of one pixel at illuminance ``lux`` (signal only)."""
        return self.parameters.optics.electrons_per_s(lux) * ELEMENTARY_CHARGE_C

    def lux_from_photocurrent(self, current_a):
        return self.parameters.optics.lux_from_electrons_per_s(
            np.asarray(current_a) / ELEMENTARY_CHARGE_C
        )

    def expected_voltages_v(self, photocurrent_a, exposure_s: float | None = None):
        """Noise-free (V1, V2, V3) for a photocurrent (A), eqs. 1–6 (dark current included)."""
        scale = 1.0 if exposure_s is None else exposure_s / self.exposure_s
        return overflow_voltages_v(
            photocurrent_a,
            self.c_pd_f,
            self.effective_overflow_capacitance_f,
            self.v_reset_v,
            self.v_f_v,
            self.v_sat_v,
            [t * scale for t in self.integration_times_s],
            self.parameters.dark_current_e_per_s * ELEMENTARY_CHARGE_C,
        )

    def expected_signal_electrons(self, photocurrent_a) -> np.ndarray:
        """Noise-free CDS signal V_res − V3 in electrons at the photodiode."""
        v3 = self.expected_voltages_v(photocurrent_a)[2]
        return (self.v_reset_v - v3) / self.parameters.conversion_gain_v_per_e

    def _circuit(self) -> tuple:
        """(C_PD, C_F, V_res, V_F, V_sat, integration times): the arguments of the closed forms
        (C_F includes the column bus)."""
        return (self.c_pd_f, self.effective_overflow_capacitance_f, self.v_reset_v, self.v_f_v, self.v_sat_v,
                self.integration_times_s)

    def dynamic_range_gain_db(self) -> float:
        """Noise-free DR gain over the plain 4T APS with the same photodiode (see
        :func:`dynamic_range_gain_db`; :func:`junction_segment_boundaries_a` when C_PD is nonlinear)."""
        if self.junction.linear:
            return dynamic_range_gain_db(*self._circuit())
        b = self.segment_boundaries_a()
        return float(20 * np.log10(b["E"] / b["I_4T"]))

    def segment_boundaries_a(self) -> dict:
        """Photocurrents at the seed's points B, C, D, E (see :func:`segment_boundaries_a`)."""
        if self.junction.linear:
            return segment_boundaries_a(*self._circuit())
        return junction_segment_boundaries_a(self.junction, self.effective_overflow_capacitance_f, self.v_f_v,
                                             self.v_sat_v, self.integration_times_s)

    def describe(self) -> dict:
        d = super().describe()
        d.update(
            model=self.name,
            integration_times_s=list(self.integration_times_s),
            overflow_capacitance_f=self.overflow_capacitance_f,
            v_f_v=self.v_f_v,
            v_reset_v=self.v_reset_v,
            v_sat_v=self.v_sat_v,
            c_pd_f=self.c_pd_f,
            share_use_time_s=self.share_use_time_s,
            row_share_time_s=self.row_share_time_s,
            ktc_noise=self.ktc_noise,
            comparator_offset_v=self.comparator_offset_v,
            comparator_noise_v=self.comparator_noise_v,
            overflow_capacitance_spread=self.overflow_capacitance_spread,
            charge_injection_electrons=self.charge_injection_electrons,
            column_bus_capacitance_f=self.column_bus_capacitance_f,
            junction_grading_m=self.junction.grading_m,
            junction_built_in_v=self.junction.built_in_v,
            reset_ktc_electrons=self.reset_ktc_electrons,
            share_ktc_electrons=self.share_ktc_electrons,
        )
        return d


def paper003_pixel_parameters(**overrides) -> FramePixelParameters:
    """The seed 003 pixel: 25 µm pitch, 20 × 20 µm photodiode, 0.35 µm CMOS (seed 003, §1).

    The seed gives no photodiode capacitance; C_PD is set so that a plain 4T APS
    integrating the whole 33.33 ms frame saturates at 8 pA (seed 003, §6), with a
    3.0 V swing (V_res = 3.3 V to V_sat = 0.3 V): C_PD = 8 pA · 33.33 ms / 3.0 V ≈ 88.9 fF.
    """
    from viform.light.radiometry import PixelOptics

    c_pd_f = 8e-12 * (1 / 30.0) / 3.0
    cg = ELEMENTARY_CHARGE_C / c_pd_f
    fw = 3.0 / cg
    kw = dict(
        optics=PixelOptics(pixel_pitch_m=25e-6, fill_factor=(20 / 25) ** 2, quantum_efficiency=0.5),
        full_well_electrons=fw,
        conversion_gain_v_per_e=cg,
        read_noise_electrons=60.0,
        dark_current_e_per_s=2000.0,
        dsnu_electrons=20.0,
        prnu_fraction=0.01,
        analog_gain=1.0,
        adc_bits=12,
        black_offset_dn=64.0,
        adc_range_v=3.2,
    )
    kw.update(overrides)
    return FramePixelParameters(**kw)


def lofic_pixel_parameters(lateral_capacitance_f: float = 500e-15, temperature_k: float = 300.0,
                           **overrides) -> FramePixelParameters:
    """The lateral-overflow-integration-capacitor (LOFIC) pixel of seed 003 Fig. 5(b) (DR_b).

    Same photodiode and readout chain as :func:`paper003_pixel_parameters` (C_PD = 88.9 fF,
    3.0 V swing, 60 e⁻ read noise at C_PD = 108 µV), plus an in-pixel C_S (default 500 fF,
    the seed's C_F) that collects the overflow during the whole integration; PD + C_S are
    read together at the low conversion gain q/(C_PD + C_S):

    * full well (C_PD + C_S)·3.0 V/q = 11.0 Me⁻ (6.6 × the 4T's 1.67 Me⁻);
    * read noise 108 µV / (q/(C_PD + C_S)) = 397 e⁻, and the readout's kTC noise of the
      total node, √2·√(kT(C_PD + C_S))/q = 436 e⁻, together 590 e⁻ rms (the 4T: 60 e⁻ plus
      √2 × 120 e⁻ when its reset noise is counted the same way).

    So the LOFIC's low end E2 sits ≈ 10 × above the 4T's E1 while its top end rises 6.6 ×:
    the compressed low-light sensitivity and SNR of the seed's DR_b.
    """
    base = paper003_pixel_parameters()
    c_pd = ELEMENTARY_CHARGE_C / base.conversion_gain_v_per_e
    c_s = check_positive("lateral_capacitance_f", lateral_capacitance_f)
    c_tot = c_pd + c_s
    cg = ELEMENTARY_CHARGE_C / c_tot
    swing_v = base.full_well_electrons * base.conversion_gain_v_per_e
    read_v = base.read_noise_electrons * base.conversion_gain_v_per_e
    ktc = np.sqrt(2.0) * ktc_noise_electrons(c_tot, temperature_k)
    kw = dict(
        optics=base.optics,
        full_well_electrons=swing_v / cg,
        conversion_gain_v_per_e=cg,
        read_noise_electrons=float(np.hypot(read_v / cg, ktc)),
        dark_current_e_per_s=base.dark_current_e_per_s,
        dsnu_electrons=base.dsnu_electrons * c_tot / c_pd,
        prnu_fraction=base.prnu_fraction,
        analog_gain=base.analog_gain,
        adc_bits=base.adc_bits,
        black_offset_dn=base.black_offset_dn,
        adc_range_v=base.adc_range_v,
    )
    kw.update(overrides)
    return FramePixelParameters(**kw)

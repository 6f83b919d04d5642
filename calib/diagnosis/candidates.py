"""The candidate library: generic physics a calibration engineer would propose.

Each candidate is a family of identification columns X(shape) (N poses, R residual rows, k
linear parameters), linear in its parameters once its shape (a pitch, a time constant, a
harmonic, a payload) is fixed. Shapes are scanned over a grid and refined on the data that
fits them; nothing here knows with which form or constants the truth twin injects effects.

Actuator-level candidates act as offsets D(pose) theta on the actuators (joint values =
commands + offsets) and show through J_act D:

* ``gain_error``        D = diag(q): a scale error of each actuator (screw pitch, gear ratio)
* ``lead_error``        sin, cos(2 pi q / pitch) per prismatic actuator, pitch scanned 2-20 mm
* ``encoder_eccentricity``  sin, cos(h q) per revolute actuator, h = 1 or 2 per revolution
* ``backlash``          -direction of approach, half play >= 0 per actuator
* ``thermal_growth``    w h(t) q on prismatic actuators (strain of each screw/leg in time)
* ``zero_drift``        u_a h(t) per actuator (each zero drifting in time)
* ``gravity_compliance`` -c_a (tau_own + m tau_payload), compliance c_a >= 0, payload m scanned;
  on a model without declared masses only a tool payload loads it: -(c_a m) tau_payload, the
  products c_a m >= 0 (mass and compliance are not separable)

with h(t) = tau (1 - exp(-t / tau)) (h = t for tau = inf: a linear drift; h'(0) = 1, so the
coefficient is the initial rate whatever tau), tau scanned over the measurement span.

Geometric candidates are columns of a richer error model (``reflector_offsets``,
``joint_axis_errors``); ``thermal_expansion`` grows the whole structure in time, every target
moving by w h(t) p (p in the base frame: the machine expands about where it stands);
``tracker_drift`` moves every reading by h(t) v; ``tracker_scale`` stretches readings about
the tracker head.
"""

from __future__ import annotations

import numpy as np

from calib.diagnosis.candidate import (
    Candidate,
    Columns,
)
from calib.diagnosis.context import Context, approach_direction

GRAVITY_SKIPPED = (
    "gravity_compliance skipped: the model declares no masses (MuJoCo's bounded defaults), so "
    "its gravity loads would be invented"
)
GRAVITY_PAYLOAD_ONLY = (
    "gravity_compliance under a tool payload only: the model declares no masses (MuJoCo's "
    "bounded defaults), so its own weight is unknown; the payload's mass and the compliances "
    "are not separable and their products are reported"
)
PHASE_STEP = 1.0  # rad of phase slip over the stroke between neighbouring grid pitches


def _diag(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(N, A) per-actuator values -> (N, A, k) offsets, one parameter per masked actuator."""
    idx = np.flatnonzero(mask)
    out = np.zeros((values.shape[0], values.shape[1], len(idx)))
    out[:, idx, np.arange(len(idx))] = values[:, idx]
    return out


def drift_shape(t: np.ndarray, tau: float) -> np.ndarray:
    """h(t) = tau (1 - exp(-t / tau)), h(t) = t for tau = inf: unit initial rate."""
    t = np.asarray(t, dtype=float)
    if not np.isfinite(tau):
        return t
    return tau * -np.expm1(-t / tau)


def _tau_grid(ctx: Context) -> np.ndarray:
    span = max(float(np.ptp(ctx.time)), 1e-9)
    return np.concatenate([span * np.geomspace(0.03, 5.0, 14), [np.inf]])


def _pitch_grid(ctx: Context) -> np.ndarray:
    """Pitches 2-20 mm, uniform in 1/pitch with a phase slip of PHASE_STEP over the stroke
    (a sinusoid 0.5 rad off the nearest grid pitch still correlates 0.99 with it; the
    finalists are refined between their grid neighbours)."""
    q = ctx.commands[:, ctx.is_slide]
    stroke = max(float(np.max(np.ptp(q, axis=0))) if q.size else 0.0, 1e-3)
    step = PHASE_STEP / (2 * np.pi * stroke)
    freq = np.arange(1 / 20e-3, 1 / 2e-3 + step, step)
    return 1.0 / freq


def _payload_grid(ctx: Context) -> np.ndarray:
    mass = ctx.gravity.moving_mass_kg if ctx.gravity is not None else 1.0
    return mass * np.array([0.0, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0])


def _gain(ctx: Context, shape: float) -> np.ndarray:
    return _diag(ctx.commands, np.ones(ctx.commands.shape[1], bool))


def _lead(ctx: Context, pitch: float) -> np.ndarray:
    return _sin_cos(2 * np.pi * ctx.commands / pitch, ctx.is_slide)


def _lead_many(ctx: Context, pitches: np.ndarray) -> np.ndarray:
    """:func:`_lead` at every pitch (N, S, A, k): the same phases, element by element."""
    return _sin_cos((2 * np.pi * ctx.commands)[:, None, :] / pitches[None, :, None], ctx.is_slide)


def _lead_pairs(ctx: Context, pitches: np.ndarray):
    """:func:`_lead_many` as its (actuator, parameter) pairs (sin of each prismatic actuator,
    then cos): the same phases and sines, without the zeros of the (N, S, A, k) array."""
    idx = np.flatnonzero(ctx.is_slide)
    phase = (2 * np.pi * ctx.commands)[:, None, :] / pitches[None, :, None]
    part = phase[..., idx]  # contiguous, as _sin_cos takes it
    o = np.concatenate([np.sin(part), np.cos(part)], axis=2)
    return o, np.concatenate([idx, idx]), np.arange(2 * len(idx)), 2 * len(idx)


def _eccentricity(ctx: Context, harmonic: float) -> np.ndarray:
    return _sin_cos(harmonic * ctx.commands, ~ctx.is_slide)


def _sin_cos(phase: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(..., A) phases -> (..., A, 2m) offsets: sin of each masked actuator's phase, then cos
    (``concatenate([_diag(sin), _diag(cos)])`` written into one array)."""
    idx = np.flatnonzero(mask)
    out = np.zeros((*phase.shape, 2 * len(idx)))
    cols = np.arange(len(idx))
    out[..., idx, cols] = np.sin(phase[..., idx])
    out[..., idx, len(idx) + cols] = np.cos(phase[..., idx])
    return out


def _backlash(ctx: Context, shape: float) -> np.ndarray:
    d = approach_direction(ctx.commands, ctx.time, ctx.previous)
    return _diag(-d, np.ones(d.shape[1], bool))


def _thermal(ctx: Context, tau: float) -> np.ndarray:
    h = drift_shape(ctx.time, tau)[:, None]
    return (ctx.commands * ctx.is_slide * h)[:, :, None]


def _zero_drift(ctx: Context, tau: float) -> np.ndarray:
    h = drift_shape(ctx.time, tau)[:, None] * np.ones_like(ctx.commands)
    return _diag(h, np.ones(ctx.commands.shape[1], bool))


def _gravity(ctx: Context, payload: float) -> np.ndarray:
    assert ctx.gravity is not None
    tau = ctx.gravity.own + payload * ctx.gravity.unit_payload
    return _diag(-tau, np.ones(tau.shape[1], bool))


def _gravity_payload(ctx: Context, shape: float) -> np.ndarray:
    assert ctx.gravity is not None
    return _diag(-ctx.gravity.unit_payload, np.ones(ctx.gravity.unit_payload.shape[1], bool))


def _tracker_drift(ctx: Context, tau: float) -> np.ndarray:
    h = drift_shape(ctx.time, tau)
    n, r = len(h), ctx.j_act.shape[1] if ctx.j_act is not None else 3 * ctx.targets.shape[1]
    eye = np.tile(np.eye(3), (r // 3, 1))  # (R, 3)
    return h[:, None, None] * eye[None, :, :] * np.ones((n, 1, 1))


def _expansion(ctx: Context, tau: float) -> np.ndarray:
    h = drift_shape(ctx.time, tau)
    return (h[:, None] * ctx.targets.reshape(len(h), -1))[:, :, None]


def _tracker_scale(ctx: Context, shape: float) -> np.ndarray:
    lever = ctx.targets - ctx.head
    return lever.reshape(len(lever), -1, 1)


def _extra(group: str) -> Columns:
    def columns(ctx: Context, shape: float) -> np.ndarray:
        assert ctx.extra is not None
        return ctx.extra.columns[group]

    return columns


def default_candidates(
    actuators: tuple[str, ...],
    is_slide: np.ndarray | None = None,
    masses_defaulted: bool = False,
    time_unit: str = "pose",
    extra_groups: dict[str, tuple[str, ...]] | None = None,
    tracker_head: bool = False,
) -> list[Candidate]:
    """The library for a machine with these actuators (all prismatic when ``is_slide`` is
    not given), gravity compliance only for a model with declared masses."""
    a = tuple(actuators)
    slide = np.ones(len(a), bool) if is_slide is None else np.asarray(is_slide, bool)
    sl = tuple(n for n, s in zip(a, slide, strict=True) if s)
    rv = tuple(n for n, s in zip(a, slide, strict=True) if not s)
    unit = tuple("mm" if s else "deg" for s in slide)
    fac = tuple(1e3 if s else float(np.degrees(1.0)) for s in slide)
    per_t = "1/pose" if time_unit == "pose" else "1/s"
    out = [
        Candidate(
            "gain_error",
            tuple(f"{n}.gain" for n in a),
            ("ppm",) * len(a),
            (1e6,) * len(a),
            offsets=_gain,
            one_actuator=True,
            explains="command",
        ),
        Candidate(
            "backlash",
            tuple(f"{n}.half_play" for n in a),
            unit,
            fac,
            offsets=_backlash,
            one_actuator=True,
            nonnegative=(True,) * len(a),
            physics="a negative play (the actuator leading its command)",
            explains="approach direction",
        ),
        Candidate(
            "zero_drift",
            tuple(f"{n}.drift_rate" for n in a),
            tuple(f"{u}/{time_unit}" for u in unit),
            fac,
            offsets=_zero_drift,
            one_actuator=True,
            grid=_tau_grid,
            shape_name="time_constant",
            shape_unit=time_unit,
            shape_log=True,
            explains="time",
        ),
    ]
    if sl:
        lead_fac = tuple(f for f, s in zip(fac, slide, strict=True) if s) * 2
        out += [
            Candidate(
                "thermal_growth",
                ("growth_per_pose" if time_unit == "pose" else "growth_per_s",),
                (f"ppm {per_t}",),
                (1e6,),
                offsets=_thermal,
                grid=_tau_grid,
                shape_name="time_constant",
                shape_unit=time_unit,
                shape_log=True,
                explains="time",
            ),
            Candidate(
                "lead_error",
                tuple(f"{n}.lead_{c}" for c in ("sin", "cos") for n in sl),
                ("mm",) * (2 * len(sl)),
                lead_fac,
                offsets=_lead,
                one_actuator=True,
                offsets_many=_lead_many,
                offset_pairs=_lead_pairs,
                grid=_pitch_grid,
                shape_name="pitch",
                shape_unit="mm",
                shape_factor=1e3,
                explains="command modulo pitch",
            ),
        ]
    if rv:
        out.append(
            Candidate(
                "encoder_eccentricity",
                tuple(f"{n}.ecc_{c}" for c in ("sin", "cos") for n in rv),
                ("deg",) * (2 * len(rv)),
                (float(np.degrees(1.0)),) * (2 * len(rv)),
                offsets=_eccentricity,
                one_actuator=True,
                grid=lambda ctx: np.array([1.0, 2.0]),
                shape_name="harmonic",
                shape_unit="per revolution",
                explains="joint angle",
            )
        )
    if masses_defaulted:
        out.append(
            Candidate(
                "gravity_compliance",
                tuple(f"{n}.compliance_x_payload" for n in a),
                tuple(("mm/kN kg" if s else "deg/(kN m) kg") for s in slide),
                tuple(f * 1e3 for f in fac),
                offsets=_gravity_payload,
                one_actuator=True,
                nonnegative=(True,) * len(a),
                physics="a negative compliance (an actuator lengthening under its load)",
                explains="gravity load",
                notes=(GRAVITY_PAYLOAD_ONLY,),
            )
        )
    else:
        out.append(
            Candidate(
                "gravity_compliance",
                tuple(f"{n}.compliance" for n in a),
                tuple(("mm/kN" if s else "deg/(kN m)") for s in slide),
                tuple(f * 1e3 for f in fac),
                offsets=_gravity,
                one_actuator=True,
                grid=_payload_grid,
                shape_name="payload",
                shape_unit="kg",
                nonnegative=(True,) * len(a),
                physics="a negative compliance (an actuator lengthening under its load)",
                explains="gravity load",
            )
        )
    out.append(
        Candidate(
            "thermal_expansion",
            ("growth_per_pose" if time_unit == "pose" else "growth_per_s",),
            (f"ppm {per_t}",),
            (1e6,),
            columns=_expansion,
            grid=_tau_grid,
            shape_name="time_constant",
            shape_unit=time_unit,
            shape_log=True,
            explains="time",
        )
    )
    out.append(
        Candidate(
            "tracker_drift",
            ("drift_x", "drift_y", "drift_z"),
            (f"mm/{time_unit}",) * 3,
            (1e3,) * 3,
            columns=_tracker_drift,
            grid=_tau_grid,
            shape_name="time_constant",
            shape_unit=time_unit,
            shape_log=True,
            explains="time",
        )
    )
    for group, names in (extra_groups or {}).items():
        is_angle = group == "joint_axis_errors"
        out.append(
            Candidate(
                group,
                names,
                ("deg" if is_angle else "mm",) * len(names),
                (float(np.degrees(1.0)) if is_angle else 1e3,) * len(names),
                columns=_extra(group),
                explains="tool orientation",
            )
        )
    if tracker_head:
        out.append(
            Candidate(
                "tracker_scale",
                ("scale",),
                ("ppm",),
                (1e6,),
                columns=_tracker_scale,
                explains="distance from the tracker",
            )
        )
    return out


def library(ctx: Context, masses_defaulted: bool) -> list[Candidate]:
    """The library for the machine and data of ``ctx``."""
    out = default_candidates(
        ctx.actuator_names,
        ctx.is_slide,
        masses_defaulted=masses_defaulted or (ctx.gravity is not None and ctx.gravity.payload_only),
        time_unit=ctx.time_unit,
        extra_groups=None if ctx.extra is None else ctx.extra.groups,
        tracker_head=ctx.head is not None,
    )
    if ctx.gravity is None:  # no loads computed: nothing for a compliance to act on
        out = [c for c in out if c.name != "gravity_compliance"]
    return out

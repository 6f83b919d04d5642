"""The keys each study reads (SCHEMAS): every scenario file is checked against its study's."""

from __future__ import annotations

from scenarios.config.schema import (
    Key,
    Table,
    _check_effects,
    _check_estimators,
    _check_name,
    _check_noise_spec,
    _check_truth,
    unknown_name_message,
)

MAX_COUNT = 100_000
_COUNT = Key(int, required=True, min=1, max=MAX_COUNT)
_NONNEG = Key(float, min=0)
_POSITION_MM = Key(list, item=float, length=3)
_HALF_WIDTH_MM = Key(list, required=True, item=float, length=2, above=0)

_TRUTH_RANDOM = Table(
    {
        "distribution": Key(str, choices=("uniform", "gaussian")),
        "translation_mm": Key(float, required=True, min=0),
        "rotation_deg": _NONNEG,
        "encoder_mm": _NONNEG,
        "encoder_deg": _NONNEG,
    }
)


def _truth(**extra: Key | Table) -> Table:
    return Table(
        {"values_file": Key(str, path=True), "random": _TRUTH_RANDOM, **extra},
        required=True,
        check=_check_truth,
    )


def _base(**keys: Key | Table) -> Table:
    """The keys every study reads, and a study's own."""
    return Table(
        {
            "name": Key(str, check=_check_name),
            "study": Key(str, required=True),
            "description": Key(str),
            "model": Key(str, required=True, path=True),
            "error_model": Key(str, required=True, path=True),
            **keys,
        }
    )


_SEED = Key(int, required=True, min=0)
_POSE_NOISE = Table(
    {
        "kind": Key(str, required=True, choices=("uniform", "gaussian")),
        "position_mm": Key(float, required=True, min=0),
        "rotation_deg": Key(float, required=True, min=0),
    },
    required=True,
)

_ARM_TRACKER = Table(
    {
        "position_mm": Key(list, required=True, item=float, length=3),
        "rotation_deg": Key(list, required=True, item=float, length=3),
        "noise": Key(str, required=True, check=_check_noise_spec),
        "sigma_mm": Key(float, required=True, above=0),
    },
    required=True,
)
_ARM_PLAN = Table(
    {
        "calibration_poses": _COUNT,
        "test_poses": _COUNT,
        "joint_fraction": Key(float, required=True, above=0, max=1),
    },
    required=True,
)

PLACEMENTS = ("interpolated", "extrapolated", "tilted")


def _check_placements(value: list, where: str) -> list[str]:
    out = [
        f"'{where}[{i}]': " + unknown_name_message("placement", p, list(PLACEMENTS))
        for i, p in enumerate(value)
        if p not in PLACEMENTS
    ]
    if len(set(value)) != len(value):
        out.append(f"'{where}' names a placement twice")
    return out


def _liu_vs_ols_keys() -> dict[str, Key | Table]:
    """The keys of liu_vs_ols's plan and twin (its single run, draw study and regime map)."""
    return dict(
        seed=_SEED,
        truth=_truth(effects=Key(list, check=_check_effects)),
        tracker=Table(
            {
                "sigma_mm": Key(float, required=True, min=0),
                "position_mm": Key(list, required=True, item=float, length=3),
                "repeats": Key(int, min=1, max=MAX_COUNT),
            },
            required=True,
        ),
        workspace=Table({"half_width_mm": _HALF_WIDTH_MM}, required=True),
        layers=Table(
            {
                "upper": Key(float, required=True),
                "middle": Key(float, required=True),
                "lower": Key(float, required=True),
            },
            required=True,
        ),
        coarse=Table({"nodes_per_side": _COUNT, "rel_tol": Key(float, above=0)}, required=True),
        fine=Table(
            {
                "nodes_per_side": _COUNT,
                "estimators": Key(list, required=True, min_items=1, check=_check_estimators),
            },
            required=True,
        ),
        scoring=Table({"nodes_per_side": Key(int, min=1, max=MAX_COUNT)}),
    )


_ISO_TRACKER = _ARM_TRACKER
_STROKE_FRACTION = Key(float, required=True, min=0, max=1)
_ISO9283 = {
    "seed": _SEED,
    "truth": Table({"random": Table(_TRUTH_RANDOM.keys, required=True)}, required=True),
    "tracker": _ISO_TRACKER,
    "repeatability": Table(
        {"position_mm": Key(float, required=True, min=0), "rotation_deg": _NONNEG},
        required=True,
    ),
    "plan": Table(
        {"calibration_poses": _COUNT, "cycles": Key(int, required=True, min=2)}, required=True
    ),
    "cube": Table(
        {"edge_mm": Key(float, required=True, above=0), "at_stroke": _STROKE_FRACTION},
        required=True,
    ),
    "arm": Table(
        {
            "model": Key(str, required=True, path=True),
            "error_model": Key(str, required=True, path=True),
            "joint_fraction": Key(float, required=True, above=0, max=1),
            "edge_mm": Key(float, required=True, above=0),
            "at_stroke": _STROKE_FRACTION,
        },
        required=True,
    ),
}

SCHEMAS: dict[str, Table] = {
    "iso9283": _base(**_ISO9283),
    "hexapod_paper": _base(
        seed=_SEED,
        truth=_truth(),
        tracker=Table(
            {
                "position_mm": Key(list, required=True, item=float, length=3),
                "noise": Key(str, required=True, check=_check_noise_spec),
                "repeats": Key(int, min=1, max=MAX_COUNT),
            },
            required=True,
        ),
        pose_noise=_POSE_NOISE,
        plans=Table(
            {"noise_free_poses": _COUNT, "few_poses": _COUNT, "many_poses": _COUNT},
            required=True,
        ),
        verification=Table(
            {
                "nodes_per_axis": _COUNT,
                "orientations_per_node": _COUNT,
                "margin": Key(float, min=0, below=0.5),
                "stroke_margin_mm": _NONNEG,
            },
            required=True,
        ),
    ),
    "liu_vs_ols": _base(
        **_liu_vs_ols_keys(),
        # the single scenario needs it; the draw study (with [draws]) does without
        monte_carlo=Table({"runs": Key(int, required=True, min=2, max=MAX_COUNT)}),
        # the draw study: the whole scenario over n truth draws (seeds seed, seed + 1, ...)
        draws=Table(
            {
                "n": Key(int, required=True, min=1, max=MAX_COUNT),
                "estimators": Key(list, min_items=1, check=_check_estimators),
                "engine": Key(str, choices=("ray", "local")),
            }
        ),
        # the loop after the fine calibration (diagnosis, effect, refit, compensation)
        loop=Table({"estimator": Key(str)}),
    ),
    # liu_vs_ols's plan and twin over a grid of tracker noise and test placements
    "liu_regime": _base(
        **_liu_vs_ols_keys(),
        regime=Table(
            {
                "sigmas_mm": Key(list, required=True, item=float, min_items=1, above=0),
                "placements": Key(
                    list, required=True, item=str, min_items=1, check=_check_placements
                ),
                "draws": Key(int, required=True, min=1, max=MAX_COUNT),
                "extrapolated_offset_mm": Key(float, above=0),
                "extrapolated_side": Key(str, choices=("below", "above")),
                "stroke_margin_mm": _NONNEG,
                "tilt_deg": Key(list, item=float, length=2, min=0, below=90),
                "tilt_seed": Key(int, min=0),
                "engine": Key(str, choices=("ray", "local")),
            },
            required=True,
        ),
    ),
    "optimal_poses": _base(
        seed=_SEED,
        truth=_truth(),
        pose_noise=_POSE_NOISE,
        design=Table(
            {
                "index": Key(
                    str,
                    choices=(
                        "product",
                        "condition",
                        "min_singular",
                        "noise_amplification",
                        "d_optimality",
                    ),
                ),
                "random_starts": _COUNT,
                "initial_poses": _COUNT,
                "max_poses": _COUNT,
                "extra_random_candidates": Key(int, required=True, min=0),
            },
            required=True,
            check=lambda d, w: (
                [f"'{w}.max_poses' must be >= '{w}.initial_poses' ({d['initial_poses']})"]
                if d["max_poses"] < d["initial_poses"]
                else []
            ),
        ),
        evaluation=Table({"noise_draws": _COUNT, "random_many": _COUNT}, required=True),
    ),
    "polisher_identifiability": _base(
        plan=Table(
            {
                "layer_heights_mm": Key(list, required=True, item=float, min_items=1),
                "nodes_per_side": _COUNT,
                "half_width_mm": _HALF_WIDTH_MM,
            },
            required=True,
        ),
        checks=Table({"fd_poses": Key(int, min=1, max=MAX_COUNT)}),
        plan_comparison=Table(
            {
                "plans": Key(
                    list,
                    item=Table(
                        {
                            "layer_heights_mm": Key(list, required=True, item=float, min_items=1),
                            "nodes_per_side": _COUNT,
                        }
                    ),
                )
            }
        ),
    ),
    "serial_arm": _base(
        seed=_SEED,
        truth=Table({"random": Table(_TRUTH_RANDOM.keys, required=True)}, required=True),
        tracker=_ARM_TRACKER,
        plan=_ARM_PLAN,
        compensation=Table(
            {
                "desired_poses": _COUNT,
                "joint_fraction": Key(float, required=True, above=0, max=1),
                "stroke_margin_deg": Key(float, required=True, min=0),
                "program_targets": Key(int, min=1, max=MAX_COUNT),
            },
            required=True,
        ),
        variants=Table(
            {
                "three_reflectors": Table(
                    {
                        "model": Key(str, required=True, path=True),
                        "error_model": Key(str, required=True, path=True),
                    },
                    required=True,
                )
            },
            required=True,
        ),
    ),
    "measured_loop": _base(
        seed=_SEED,
        truth=Table(
            {
                "random": Table(_TRUTH_RANDOM.keys, required=True),
                "effects": Key(list, check=_check_effects),
            },
            required=True,
        ),
        tracker=_ARM_TRACKER,
        plan=_ARM_PLAN,
        compensation=Table(
            {
                "program_targets": _COUNT,
                "joint_fraction": Key(float, required=True, above=0, max=1),
            }
        ),
    ),
    "undeclared_effect": _base(
        seed=_SEED,
        truth=_truth(
            effects=Key(list, check=_check_effects),
            tracker_scale_error=Key(float, above=-1),
        ),
        tracker=Table(
            {"sigma_mm": Key(float, required=True, min=0), "position_mm": _POSITION_MM},
            required=True,
        ),
        plan=Table({"calibration_poses": _COUNT, "test_poses": _COUNT}, required=True),
    ),
    "diagnosis_benchmark": _base(
        machine=Key(str),
        truth=Table({"random": Table(_TRUTH_RANDOM.keys, required=True)}, required=True),
        tracker=Table(
            {"sigma_mm": Key(float, required=True, above=0), "position_mm": _POSITION_MM},
            required=True,
        ),
        plan=Table(
            {"calibration_poses": _COUNT, "test_poses": _COUNT, "audit_poses": _COUNT},
            required=True,
        ),
        benchmark=Table(
            {
                # twin effect kinds (scenarios.machine_setup.EFFECTS), each at its defaults
                "kinds": Key(
                    list,
                    required=True,
                    item=str,
                    check=lambda v, w: _check_effects([{"kind": k} for k in v], w),
                ),
                "multipliers": Key(list, required=True, item=float, min_items=1, above=0),
                "seeds": Key(list, required=True, item=int, min_items=1, min=0),
                "none_seeds": Key(list, required=True, item=int, min=0),
            },
            required=True,
        ),
        extra_machines=Key(
            list,
            item=Table(
                {
                    "label": Key(str, required=True),
                    "model": Key(str, required=True),
                    "error_model": Key(str, required=True),
                    "kinds": Key(
                        list,
                        item=str,
                        check=lambda v, w: _check_effects([{"kind": k} for k in v], w),
                    ),
                }
            ),
        ),
    ),
}


# ------------------------------------------------------------------------- the scenario

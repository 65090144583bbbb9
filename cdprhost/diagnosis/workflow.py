"""The discrepancy workflow: find the disagreement, name the effect, add it, repeat.

1. Fit the base model (the 12 geometric parameters, plus any effects the profile
   already has) and its held-out error by pose.
2. For each catalogue effect not yet in the model and not absorbed by the geometry,
   fit 'current model + effect': nested F test against the current model (Holm
   over the candidates of the round), BIC, held-out error.
3. An effect is *eligible* if its Holm-adjusted p < alpha, it lowers BIC by at
   least ``min_bic_gain`` and lowers the held-out error, and its parameters are physical. The eligible effect with the
   lowest BIC is named unless another eligible effect comes within ``bic_margin``
   BIC or beats it on held-out error and the two explain the same disagreement
   (their joint fit adds nothing significant over either): then ``ambiguous``.
4. Add the named effect and repeat while a further effect is eligible.
5. Verdict: ``ambiguous``; else ``unexplained`` if the final model still fails
   the chi-square test (p < gof_alpha); else ``named`` or ``none``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cdprhost.calibration.fitting import CableModelFit, Observations
from cdprhost.calibration.pose_noise import PoseNoise
from cdprhost.diagnosis import crossval, signatures
from cdprhost.diagnosis.effect_values import admissible, effect_parameters, geometry_parameters
from cdprhost.diagnosis.localise import Finding, describe, localise
from cdprhost.diagnosis.noise_floor import accuracy_from_fit, unseen_noise
from cdprhost.diagnosis.stat_tests import bic, goodness_of_fit_p, holm, nested_f_test
from cdprhost.effects.registry import CATALOGUE
from cdprhost.errors import InputError
from cdprhost.kinematics.machine import MachineModel

MIN_POSES = 8


@dataclass(frozen=True)
class DiagnosisSettings:
    folds: int = 8
    alpha: float = 0.01
    gof_alpha: float = 1e-3
    bic_margin: float = 10.0
    min_bic_gain: float = 10.0  # an effect must lower BIC by at least this ("very strong" evidence)
    heldout_tol: float = 0.05
    max_rounds: int = 3
    candidates: tuple[str, ...] | None = None  # default: the whole catalogue
    confusable_threshold: float = 0.9
    localise_alpha: float = 0.01
    heldout_for_all: bool = True  # False: cross-validate only candidates that pass the F test


DEFAULT_SETTINGS = DiagnosisSettings()
#: Settings for many repeated diagnoses (tests, benchmarks): fewer folds, same decisions.
FAST = DiagnosisSettings(folds=4, heldout_for_all=False)


@dataclass
class ModelResult:
    """One fitted model ('geometry + effects') and its held-out errors by pose."""

    effects: tuple[str, ...]
    fit: CableModelFit
    heldout_errors_mm: np.ndarray | None

    @property
    def n_params(self) -> int:
        return len(self.fit.x_)

    @property
    def chi2(self) -> float:
        return self.fit.chi2_

    @property
    def dof(self) -> int:
        return int(self.fit.dof_)

    @property
    def bic(self) -> float:
        return bic(self.fit.chi2_, self.n_params, self.fit.n_obs_)

    @property
    def gof_p(self) -> float:
        return goodness_of_fit_p(self.fit.chi2_, self.fit.dof_)

    @property
    def heldout_rms_mm(self) -> float:
        return (
            float("nan") if self.heldout_errors_mm is None else crossval.rms(self.heldout_errors_mm)
        )


@dataclass
class Candidate:
    name: str
    round: int
    result: ModelResult | None = None
    f_stat: float = float("nan")
    p_value: float = float("nan")
    p_holm: float = float("nan")
    delta_bic: float = float("nan")
    unabsorbed: float = float("nan")
    admissible: bool = True
    status: str = (
        "not significant"  # named | rival | significant | not significant | absorbed | non-physical
    )

    @property
    def heldout_rms_mm(self) -> float:
        return float("nan") if self.result is None else self.result.heldout_rms_mm


@dataclass(frozen=True)
class Step:
    """The model after one step of the forward selection (the base model first) and the gap
    it leaves: held-out error against the noise floor a correct model would reach."""

    effects: tuple[str, ...]
    heldout_rms_mm: float
    noise_floor_mm: float
    chi2: float
    dof: int
    gof_p: float
    p_value: float = float("nan")  # F test of the effect added, against the previous step
    delta_bic: float = float("nan")

    def as_dict(self) -> dict[str, Any]:
        return {
            "effects": list(self.effects),
            "added": self.effects[-1] if self.effects else None,
            "heldout_rms_mm": self.heldout_rms_mm,
            "noise_floor_mm": self.noise_floor_mm,
            "gap_mm": self.heldout_rms_mm - self.noise_floor_mm,
            "chi2": self.chi2,
            "dof": self.dof,
            "p_value_fit": self.gof_p,
            "p_value_added": self.p_value,
            "delta_bic": self.delta_bic,
        }


@dataclass
class Diagnosis:
    verdict: str  # named | none | ambiguous | unexplained
    effects: tuple[str, ...]  # named effects, in the order they were added
    ambiguous_between: tuple[str, ...]
    rounds: list[list[Candidate]]
    base: ModelResult
    final: ModelResult
    noise: PoseNoise
    noise_floor_mm: float
    noise_floor_base_mm: float
    expected_heldout_mm: np.ndarray  # per pose, for a correct final model
    parameters: dict[str, Any]
    where: str
    findings: list[Finding]
    signatures: dict[str, signatures.SignatureReport]
    confusable: list[tuple[str, str, float]]
    n_poses: int
    settings: DiagnosisSettings = field(default_factory=DiagnosisSettings)
    steps: list[Step] = field(default_factory=list)

    @property
    def effect(self) -> str | None:
        return self.effects[0] if self.verdict == "named" else None

    @property
    def candidates(self) -> list[Candidate]:
        """The first round's candidates (each tested against the base model)."""
        return self.rounds[0] if self.rounds else []

    @property
    def final_model(self) -> MachineModel:
        return self.final.fit.model_


def fit_model(
    obs: Observations,
    start: MachineModel,
    effects: Sequence[str],
    folds: Sequence[np.ndarray] | None,
) -> ModelResult:
    fit = CableModelFit(effects=tuple(effects)).fit(obs, start)
    errors = None if folds is None else crossval.heldout_errors(obs, fit.model_, effects, folds)
    return ModelResult(tuple(effects), fit, errors)


class _Round:
    """Evaluate and rank the candidates of one round against the current model."""

    def __init__(
        self,
        obs: Observations,
        current: ModelResult,
        names: Sequence[str],
        index: int,
        folds: Sequence[np.ndarray],
        settings: DiagnosisSettings,
        unabsorbed: dict[str, float],
    ):
        self.obs, self.current, self.folds, self.settings = obs, current, folds, settings
        self.candidates = [self._evaluate(n, index, unabsorbed.get(n, float("nan"))) for n in names]
        for c, p in zip(self.candidates, holm([c.p_value for c in self.candidates])):
            c.p_holm = float(p)
            if p < settings.alpha and c.result is not None and c.result.heldout_errors_mm is None:
                c.result.heldout_errors_mm = crossval.heldout_errors(
                    obs, c.result.fit.model_, c.result.effects, folds
                )
            if not c.admissible:
                c.status = "non-physical"
            elif p < settings.alpha:
                c.status = "significant"

    def _evaluate(self, name: str, index: int, unabsorbed: float) -> Candidate:
        effects = self.current.effects + (name,)
        fit = CableModelFit(effects=effects).fit(self.obs, self.current.fit.model_)
        errors = (
            crossval.heldout_errors(self.obs, fit.model_, effects, self.folds)
            if self.settings.heldout_for_all
            else None
        )
        result = ModelResult(effects, fit, errors)
        extra = result.n_params - self.current.n_params
        f, p = nested_f_test(self.current.chi2, result.chi2, extra, result.dof)
        return Candidate(
            name,
            index,
            result,
            f,
            p,
            delta_bic=result.bic - self.current.bic,
            unabsorbed=unabsorbed,
            admissible=admissible(fit, name),
        )

    def eligible(self) -> list[Candidate]:
        cur = self.current.heldout_rms_mm
        ok = [
            c
            for c in self.candidates
            if c.status == "significant"
            and c.delta_bic < -self.settings.min_bic_gain
            and c.result is not None
            and c.heldout_rms_mm < cur
        ]
        return sorted(ok, key=lambda c: c.delta_bic)

    def same_disagreement(self, best: Candidate, rival: Candidate) -> bool:
        """True when best and rival explain the same thing: their joint fit is not
        significantly better than both of them alone."""
        if best.result is None or rival.result is None:
            return False
        joint = CableModelFit(effects=best.result.effects + (rival.name,)).fit(
            self.obs, best.result.fit.model_
        )
        _, p_over_best = nested_f_test(
            best.result.chi2, joint.chi2_, len(joint.x_) - best.result.n_params, joint.dof_
        )
        _, p_over_rival = nested_f_test(
            rival.result.chi2, joint.chi2_, len(joint.x_) - rival.result.n_params, joint.dof_
        )
        return not (p_over_best < self.settings.alpha and p_over_rival < self.settings.alpha)


TAKES_ONLY = "takes"


#: Sources of a noise model that knows nothing of the system's accuracy at each place: the
#: accuracy is then estimated here (from the richest model).
UNSEEN_ACCURACY = ("takes", "camera")
#: The richest model must leave at least this many degrees of freedom to estimate it.


def observations_check(obs: Observations) -> None:
    if len(obs) < MIN_POSES:
        raise InputError(
            f"a diagnosis needs at least {MIN_POSES} measured poses, got {len(obs)} (a "
            "calibration's default is 4 fit + 3 check poses): record a session with more, "
            "e.g. `cdprhost calibrate wizard --profile P --session NEW_DIR --poses 12` "
            "(12 fit + 3 check poses), or try one of the simulated world: "
            "`cdprhost calibrate demo --profile P --out DIR`"
        )
    for label, arr in (("measured points", obs.measured), ("commanded sliders", obs.sliders)):
        bad = np.flatnonzero(~np.isfinite(np.asarray(arr, float)).all(axis=1))
        if bad.size:
            raise InputError(
                f"{label} are not finite at pose(s) {', '.join(str(i + 1) for i in bad[:10])}"
            )


def diagnose(
    obs: Observations,
    base_model: MachineModel,
    noise: PoseNoise | None = None,
    settings: DiagnosisSettings = DEFAULT_SETTINGS,
) -> Diagnosis:
    """Run the whole workflow on measured poses; ``base_model`` gives the starting geometry
    and any effects already in the profile (refitted, not tested)."""
    observations_check(obs)
    if noise is None:
        sig = np.broadcast_to(np.asarray(obs.sigma_mm, dtype=float), (len(obs),)).copy()
        noise = PoseNoise(sig, sig, 0.0, "given", "noise given with the observations")
    folds = crossval.pose_folds(len(obs), settings.folds)
    base = fit_model(obs, base_model, base_model.effects.names, folds)

    names = [n for n in (settings.candidates or tuple(CATALOGUE)) if n not in base.effects]
    reports = {
        n: signatures.analyse_signature(
            n, *signatures.effect_signature(base.fit.model_, obs, CATALOGUE[n])
        )
        for n in names
    }
    confusable = signatures.confusable_pairs(list(reports.values()), settings.confusable_threshold)
    remaining = [n for n in names if not reports[n].absorbed]
    unabsorbed = {n: r.unabsorbed_min for n, r in reports.items()}
    if noise.source in UNSEEN_ACCURACY:
        accurate = accuracy_from_fit(
            obs,
            base.fit.model_,
            base.effects + tuple(remaining),
            noise,
            settings.gof_alpha,
            settings.localise_alpha,
        )
        if accurate is not None:
            return diagnose(
                obs.with_sigma(accurate.sigma_mm),
                base_model,
                accurate,
                settings,
            )

    current: ModelResult = base
    named: list[str] = []
    ambiguous: tuple[str, ...] = ()
    rounds: list[list[Candidate]] = []
    added: list[Candidate] = []
    for index in range(settings.max_rounds):
        if not remaining:
            break
        rnd = _Round(obs, current, remaining, index + 1, folds, settings, unabsorbed)
        rounds.append(rnd.candidates)
        eligible = rnd.eligible()
        if not eligible:
            break
        best = eligible[0]
        rivals = [
            c
            for c in eligible[1:]
            if (
                c.delta_bic - best.delta_bic < settings.bic_margin
                or c.heldout_rms_mm < best.heldout_rms_mm * (1 - settings.heldout_tol)
            )
            and rnd.same_disagreement(best, c)
        ]
        if rivals:
            for c in (best, *rivals):
                c.status = "rival"
            ambiguous = (best.name, *(c.name for c in rivals))
            break
        best.status = "named"
        named.append(best.name)
        added.append(best)
        if best.result is None:  # eligible candidates always carry their fit
            break
        current = best.result
        remaining.remove(best.name)

    absorbed = [
        Candidate(n, 1, unabsorbed=unabsorbed[n], status="absorbed")
        for n in names
        if reports[n].absorbed
    ]
    if absorbed:
        rounds = [rounds[0] + absorbed, *rounds[1:]] if rounds else [absorbed]
    if ambiguous:
        verdict = "ambiguous"
    elif current.gof_p < settings.gof_alpha:
        verdict = "unexplained"
        if noise.source == TAKES_ONLY and not localise(
            current.fit.model_, obs, settings.localise_alpha
        ):
            # The takes cannot see an error that stays fixed during a take (repeatability,
            # calibration of the mocap): an excess with no pattern is that, not physics.
            wider = unseen_noise(current.fit, obs, noise)
            return diagnose(
                obs.with_sigma(wider.sigma_mm),
                base_model,
                wider,
                settings,
            )
    else:
        verdict = "named" if named else "none"

    # the disagreement described: what is left for 'unexplained', what was found otherwise
    described = current if verdict == "unexplained" else base
    findings = localise(described.fit.model_, obs, settings.localise_alpha)
    where = describe(
        findings,
        described.chi2,
        described.dof,
        described.gof_p,
        gof_alpha=settings.gof_alpha,
        explained=bool(named) or bool(ambiguous),
    )
    if verdict == "named":
        where += f"; explained by {' + '.join(named)}"

    sigma = obs.sigma_mm
    jac_final = signatures.fit_jacobian(current.fit, obs)
    expected = crossval.expected_heldout_sq(jac_final, sigma, folds)
    floor_base = crossval.noise_floor_mm(signatures.fit_jacobian(base.fit, obs), sigma, folds)
    floors = [floor_base] + [
        crossval.noise_floor_mm(signatures.fit_jacobian(c.result.fit, obs), sigma, folds)
        for c in added[:-1]
        if c.result is not None
    ]
    floors.append(float(np.sqrt(np.mean(expected))))
    steps = [_step(base, floors[0])] + [
        _step(c.result, f, c) for c, f in zip(added, floors[1:]) if c.result is not None
    ]
    params = {"geometry": geometry_parameters(current.fit)}
    params.update({n: effect_parameters(current.fit, n) for n in current.effects})
    return Diagnosis(
        verdict=verdict,
        effects=tuple(named),
        ambiguous_between=tuple(ambiguous),
        rounds=rounds,
        base=base,
        final=current,
        noise=noise,
        noise_floor_mm=float(np.sqrt(np.mean(expected))),
        noise_floor_base_mm=floor_base,
        expected_heldout_mm=np.sqrt(expected),
        parameters=params,
        where=where,
        findings=findings,
        signatures=reports,
        confusable=confusable,
        n_poses=len(obs),
        settings=settings,
        steps=steps,
    )


def _step(result: ModelResult, floor: float, added: Candidate | None = None) -> Step:
    return Step(
        result.effects,
        result.heldout_rms_mm,
        floor,
        result.chi2,
        result.dof,
        result.gof_p,
        added.p_value if added else float("nan"),
        added.delta_bic if added else float("nan"),
    )

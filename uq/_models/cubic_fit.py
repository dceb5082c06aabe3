"""Fitting the per-pressure cubics: one test, several tests in one emcee run, a campaign.

Each test is fitted by the variant its readings call for (``fit_tests``): the plain model
(``uq._models.cubic``), the force alone (``uq._models.cubic_force``), the measured pressure as a
covariate (``uq._models.cubic_measured``) or AR(1) pressure-holding errors
(``uq._models.cubic_ar1``); the results are ``uq._models.cubic_results``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from uq._data.recordings import PressureTest, Recordings
from uq._data.reference import PAPER_PISTON_AREA_M2
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel, fit_collapsed
from uq._inference.sampler import Settings
from uq._models.cubic import MAX_DRAWS, MODEL, CubicData, VolumeData, basis, prepare
from uq._models.cubic_ar1 import AR1, AR1Data, ar1_data, ar1_order_whitening, prewhiten
from uq._models.cubic_force import FORCE_ONLY, ForceData, force_data
from uq._models.cubic_measured import MEASURED, MeasuredData, measured_corrected, measured_data
from uq._models.cubic_results import CampaignFit, PressureFit
from uq._models.residual_order import ALPHA as ORDER_ALPHA
from uq._models.residual_order import ORDER_UNKNOWN, lag_one_check
from uq._models.saved import provenance_of
from uq._physics.cubic import cubic
from uq._physics.quantities import force_noise_var


def test_seeds(seed: int, n: int) -> list[int]:
    """Independent per-test seeds derived from one campaign seed."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(n)]


PRESSURE_MODELS = ("set", "measured")
AR1_CHOICES = ("off", "on", "auto")


@dataclasses.dataclass(frozen=True)
class _Item:
    """One test to fit, with what its campaign says about it."""

    test: PressureTest
    x0_m: float
    piston_area_m2: float
    pressure: str  # "set" or "measured"
    seed: int  # of its exact coefficient draws


def fit_tests(
    tests,
    x0_m: float,
    *,
    seed: int,
    settings: Settings = Settings(),
    noise: str = "budget",
    stand: StandDescription = PAPER_STAND,
    desc: str | None = None,
    pressure: str = "set",
    ar1: str = "off",
    piston_area_m2: float = PAPER_PISTON_AREA_M2,
) -> list[PressureFit]:
    """Fit several tests at once: one emcee run samples every test's ensembles in lockstep
    (``fit_collapsed`` with a list of data), each test with its own independent ensembles,
    burn-in and convergence verdict. The exact coefficient draws of test i use the i-th seed
    derived from ``seed`` (:func:`test_seeds`).

    ``noise="budget"`` (default): force sd grows with the force (load cell) over a floor.
    ``noise="constant"``: one force sd for the whole test, the common but wrong choice kept
    for the calibration suite's misspecification study (the total is still sampled; its split
    into floor and relative parts is then unidentified and follows the prior).

    The pressure-holding error (the pressure-holding section below): ``pressure="measured"`` uses each
    reading's measured pressure (``PressureTest.measured_pressure_bar``) as a covariate; otherwise
    ``ar1`` says whether the holding errors are an AR(1) series in recording order: "off" (in the
    independent noise, the default), "on" (every test with a recording order), "auto" (the tests
    whose residuals the recording-order check flags under the independent model are refitted
    with it). Tests without a recording order keep the plain model for AR(1). Force-only tests (no
    piston_* and no volume_* column) are fitted by ``FORCE_ONLY`` (the force block; with measured
    pressures as its covariate under ``pressure="measured"``); a test with a volume column fits
    L = -V / S (:func:`piston_coordinate`) with the plain model (its volume was not read off the
    stand's piston, so the pressure-holding terms do not apply to it). ``piston_area_m2``: the
    stand's S (Boyle's law moves the piston by dV / S; a volume column's L = -V / S).
    """

    tests = list(tests)  # pressure and ar1 are checked by _fit_items
    items = [
        _Item(t, x0_m, piston_area_m2, pressure, s)
        for t, s in zip(tests, test_seeds(seed, len(tests)), strict=True)
    ]
    return _fit_items(
        items, seed=seed, settings=settings, noise=noise, stand=stand, desc=desc, ar1=ar1
    )


#: the model of each variant (the key :func:`_variant_of` gives a test)
_MODELS = {
    "plain": MODEL,
    "volume": MODEL,  # the plain model on VolumeData: L's rounding in its noise
    "measured": MEASURED,
    "ar1": AR1,
    "force": FORCE_ONLY,
    "force-measured": FORCE_ONLY,
}
#: the pressure-holding treatment PressureFit.variant records for each model key
_HOLDING = {"force": "plain", "force-measured": "measured", "volume": "plain"}
#: how the sampler's independence move fits its proposal for each model key
#: (uq._inference.sampler.PROPOSALS; "half" where not named). AR(1): "held", the Yeo-Johnson t
#: fitted in the burn-in to each ensemble's own draws: sigma_L's posterior has a long left tail
#: where the holding-error series takes the piston's scatter and sigma_L falls back to its prior
#: (seed 20201 of the rough-stand calibration, replication 90: 5-50-95 % of log sigma_L at
#: -11.3, -6.6, -6.2), which a Student t refitted to half the ensemble at every step follows so
#: badly that the acceptance stayed at 0.12 (every walker 0.10-0.14) and the fit failed the
#: acceptance rule after 3352 steps (tau 55); held: 0.21, tau 17, converged after 1200 steps
#: (tests/models/test_cubic_pressure.py)
_PROPOSALS = {"ar1": "held"}


def _variant_of(item: _Item, ar1: str) -> str:
    t = item.test
    if t.piston_m is None and t.volume_m3 is None:  # force only
        return "force-measured" if item.pressure == "measured" else "force"
    if t.piston_m is None:  # L from a volume column: not read off the stand's piston
        return "volume"
    if item.pressure == "measured":
        return "measured"
    if ar1 == "on" and t.step is not None:
        return "ar1"
    return "plain"


def _data_of(item: _Item, variant: str, noise: str, stand: StandDescription):
    t, x0_m, area = item.test, item.x0_m, item.piston_area_m2
    if variant == "measured":
        return measured_data(t, x0_m, noise, stand, area)
    if variant == "ar1":
        return ar1_data(t, x0_m, noise, stand, area)
    if variant in ("force", "force-measured"):
        return force_data(t, x0_m, noise, stand, measured=variant == "force-measured")
    return prepare(t, x0_m, noise, stand, area)  # the plain model


def _fit_items(
    items: list[_Item],
    *,
    seed: int,
    settings: Settings,
    noise: str,
    stand: StandDescription,
    desc: str | None,
    ar1: str,
) -> list[PressureFit]:
    """The tests ``items`` (of one campaign or of several) in one emcee run per model variant,
    seeded by ``seed``; each test's exact coefficient draws by its own ``item.seed``."""
    if ar1 not in AR1_CHOICES:
        raise ValueError(f"ar1 must be one of {AR1_CHOICES}, got {ar1!r}")
    for it in items:
        if it.pressure not in PRESSURE_MODELS:
            raise ValueError(f"pressure must be one of {PRESSURE_MODELS}, got {it.pressure!r}")
    variants = [_variant_of(it, ar1) for it in items]

    def run(indices, variant, label):
        prepared = [_data_of(items[i], variant, noise, stand) for i in indices]
        posts = fit_collapsed(
            _MODELS[variant],
            [p[0] for p in prepared],
            seed=seed,
            settings=settings,
            max_draws=MAX_DRAWS,
            seeds=[items[i].seed for i in indices],
            desc=label,
            proposal=_PROPOSALS.get(variant, "half"),
        )
        return {
            i: with_order_check(
                PressureFit.of(
                    items[i].test,
                    items[i].x0_m,
                    lsq_f,
                    lsq_l,
                    post,
                    ref,
                    noise,
                    _HOLDING.get(variant, variant),
                )
            )
            for i, (_, lsq_f, lsq_l, ref), post in zip(indices, prepared, posts, strict=True)
        }

    fits: dict[int, PressureFit] = {}
    for variant in _MODELS:
        idx = [i for i, v in enumerate(variants) if v == variant]
        if idx:
            fits |= run(
                idx, variant, desc if variant == "plain" else f"{desc or 'sampling'} ({variant})"
            )
    if ar1 == "auto":
        flagged = [
            i
            for i, f in fits.items()
            if f.variant == "plain"
            and items[i].pressure != "measured"
            and items[i].test.step is not None
            and items[i].test.piston_m is not None
            and f.model_warnings()
        ]
        if flagged:
            fits |= run(flagged, "ar1", f"{desc or 'sampling'} (AR(1) where flagged)")
    return [fits[i] for i in range(len(items))]


def fit_test(
    test: PressureTest,
    x0_m: float,
    *,
    seed: int,
    settings: Settings = Settings(),
    noise: str = "budget",
    stand: StandDescription = PAPER_STAND,
    pressure: str = "set",
    ar1: str = "off",
) -> PressureFit:
    """One test's posterior (:func:`fit_tests` of one test)."""
    return fit_tests(
        [test],
        x0_m,
        seed=seed,
        settings=settings,
        noise=noise,
        stand=stand,
        pressure=pressure,
        ar1=ar1,
    )[0]


def fit_campaign(
    recordings: Recordings,
    *,
    seed: int = 0,
    settings: Settings = Settings(),
    stand: StandDescription = PAPER_STAND,
    pressure_ar1: str = "off",
) -> CampaignFit:
    """Fit every test of a campaign: one emcee run samples all tests in lockstep, each with its
    own ensembles and convergence checks (:func:`fit_tests`). ``stand``: the stand the recordings
    were taken on (its load cell centres the prior of the relative force noise). ``uq fit`` is
    this plus :meth:`CampaignFit.to_json`. Recordings with measured pressures
    (``Recordings.pressure_measured``) use them as a covariate of the pressure-holding error;
    otherwise ``pressure_ar1`` ("off", "on", "auto") models the holding errors as an AR(1) series
    in recording order (:func:`fit_tests`). The same as ``fit_campaigns([recordings], [seed])[0]``.

    >>> import uq
    >>> rec = uq.simulate("n50", seed=1, layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
    >>> fit = uq.fit_campaign(rec, seed=1, settings=uq.Settings(max_steps=200))
    >>> [t.pressure_bar for t in fit.tests], fit.at(5.0).flat("force").shape[1]
    ([1.0, 5.0], 4)
    >>> a_P = fit.at(5.0).flat("force")[:, 0]   # posterior draws of a_P, the force at x0 (N)
    >>> bool(12e3 < a_P.mean() < 14e3)
    True
    """
    return fit_campaigns(
        [recordings], [seed], settings=settings, stand=stand, pressure_ar1=pressure_ar1
    )[0]


def fit_campaigns(
    recordings: list[Recordings],
    seeds: list[int],
    *,
    settings: Settings = Settings(),
    stand: StandDescription = PAPER_STAND,
    pressure_ar1: str = "off",
    desc: str | None = None,
) -> list[CampaignFit]:
    """Fit many campaigns through one driver call: the tests of every campaign are sampled in
    one emcee run per model variant (as the tests of one campaign are, :func:`fit_tests`), each
    test with its own ensembles, burn-in and convergence verdict, its campaign's x0, piston area
    and pressure treatment, and its exact coefficient draws seeded by its campaign's seed
    (:func:`test_seeds` of it). ``uq batch`` fits its campaigns this way.

    Determinism: the emcee random stream is shared by the run and seeded by ``seeds[0]``, so a
    campaign's MCMC draws depend on the campaigns it was batched with (the same list gives the
    same draws, to the bit on one machine); ``fit_campaigns([rec], [seed])[0]`` is
    :func:`fit_campaign` ``(rec, seed=seed)``, draw for draw. The run is extended until every
    test of every campaign passes the convergence rules (or ``max_steps``), so one slow test
    lengthens the run of all; the retained draws are thinned to the same count either way.
    All campaigns share ``settings`` and ``stand`` (group campaigns by them before calling). An
    error in any campaign's data (e.g. a MAP that does not converge) is raised for the whole
    call: fit the campaigns one by one to know whose it was.
    """
    recordings, seeds = list(recordings), [int(s) for s in seeds]
    if len(recordings) != len(seeds):
        raise ValueError(f"{len(recordings)} recordings but {len(seeds)} seeds")
    if not recordings:
        return []
    items, spans = [], []
    for rec, seed in zip(recordings, seeds, strict=True):
        pressure = "measured" if getattr(rec, "pressure_measured", False) else "set"
        area = getattr(rec, "piston_area_m2", PAPER_PISTON_AREA_M2)
        first = len(items)
        items += [
            _Item(t, rec.x0_m, area, pressure, s)
            for t, s in zip(rec.tests, test_seeds(seed, len(rec.tests)), strict=True)
        ]
        spans.append((first, len(items)))
    if desc is None:
        desc = (
            "sampling all tests"
            if len(recordings) == 1
            else f"sampling {len(recordings)} campaigns"
        )
    fits = _fit_items(
        items,
        seed=seeds[0],
        settings=settings,
        noise="budget",
        stand=stand,
        desc=desc,
        ar1=pressure_ar1,
    )
    return [
        CampaignFit(
            rec,
            fits[a:b],
            seed,
            stand,
            provenance_of(rec, seed=seed, settings=settings, stand=stand),
        )
        for rec, seed, (a, b) in zip(recordings, seeds, spans, strict=True)
    ]


def with_order_check(fit: PressureFit) -> PressureFit:
    """The fit with its recording-order check (uq._models.residual_order), or the reason it is
    skipped for a test in unknown order."""
    check = {"skipped": ORDER_UNKNOWN} if fit.test.step is None else order_check(fit)
    return dataclasses.replace(fit, order_check=check | {"alpha": ORDER_ALPHA})


def order_check(fit: PressureFit) -> dict:
    """The recording-order check of each block's residuals under the fitted model."""
    test, x0_m, posterior, ref_force_N = fit.test, fit.x0_m, fit.posterior, fit.ref_force_N
    variant, force, piston, noise = fit.variant, fit.force, fit.piston, fit.noise
    piston_m = fit.piston_m
    blocks = ("force", "piston") if fit.has_piston else ("force",)
    u = test.height_m - x0_m
    mean_noise = noise.reshape(-1, noise.shape[-1]).mean(axis=0)
    design = np.asarray(basis(u))
    readings = {"force": test.force_N, "piston": piston_m}
    beta_mean = posterior.beta.reshape(-1, posterior.beta.shape[-1]).mean(0)
    if variant == "measured" and "piston" in blocks:  # corrected by the measured pressure
        readings = measured_corrected(posterior.data, beta_mean)
    elif variant == "measured":  # force only: the offset is the fifth coefficient
        d = posterior.data
        readings = {"force": np.asarray(d.y) - np.asarray(d.X)[:, 4] * beta_mean[4]}
    residuals = {"force": readings["force"] - cubic(force.reshape(-1, 4).mean(0), u)}
    sd = {"force": np.sqrt(force_noise_var(mean_noise[0], mean_noise[1], ref_force_N))}
    if "piston" in blocks:
        residuals["piston"] = readings["piston"] - cubic(piston.reshape(-1, 4).mean(0), u)
        sd["piston"] = np.full(u.shape, mean_noise[2])
    designs = {b: design for b in blocks}
    if variant == "ar1":  # check what the AR(1) model leaves: Prais-Winsten innovations
        theta_mean = posterior.theta.reshape(-1, posterior.theta.shape[-1]).mean(0)
        rho, sd = ar1_order_whitening(posterior.data, theta_mean)
        for b in blocks:
            residuals[b] = prewhiten(residuals[b] / sd[b], rho[b])
            designs[b] = np.stack(
                [prewhiten(c, rho[b]) for c in (design / sd[b][:, None]).T], axis=1
            )
            sd[b] = np.ones(u.shape)
    return {b: lag_one_check(residuals[b], sd[b], designs[b]) for b in blocks}


def collapsed_model(data) -> CollapsedModel:
    """The model bundle whose data ``data`` is (a fit's ``posterior.data``), for refits."""
    kinds = (
        (ForceData, FORCE_ONLY),
        (MeasuredData, MEASURED),
        (AR1Data, AR1),
        (CubicData, MODEL),
        (VolumeData, MODEL),
    )
    for kind, model in kinds:
        if isinstance(data, kind):
            return model
    raise TypeError(f"not the data of a per-pressure cubic: {type(data).__name__}")

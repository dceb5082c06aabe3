"""The one fit driver (uq/_inference/collapsed.py): overdispersed starts in every coordinate, and
saved posteriors that ArviZ's own tools (az.loo, az.plot_ppc) work on."""

from __future__ import annotations

import numpy as np

import uq

LAYOUT = uq.Layout(pressures_bar=(5.0,), step_m=0.005)


def test_starts_are_overdispersed_in_every_coordinate():
    """The walkers start from the Laplace covariance widened by init_spread (3): in every sampled
    coordinate, the weakly identified floor share included (its starts were about 20 times too
    tight when every coordinate got one fixed width), the starts are at least twice as wide as the
    posterior they converge to."""
    fit = uq.fit_test(uq.simulate("n50", seed=4, layout=LAYOUT).tests[0], 0.112, seed=4)
    chains = fit.chains
    start_sd = chains.start.std(axis=1).mean(axis=0)  # per coordinate, over each ensemble's walkers
    post_sd = chains.samples.reshape(-1, chains.samples.shape[-1]).std(axis=0)
    assert np.all(start_sd > 2.0 * post_sd), dict(
        zip(chains.names, start_sd / post_sd, strict=True)
    )


def test_saved_posteriors_work_with_arviz(tmp_path):
    """uq fit --out writes InferenceData with posterior, log_likelihood, posterior_predictive and
    observed_data groups: az.loo and az.plot_ppc run on the file as saved."""
    import warnings

    import arviz as az
    import matplotlib

    matplotlib.use("Agg")
    rec = uq.simulate("n50", seed=5, layout=LAYOUT)
    fit = uq.fit_campaign(rec, seed=5, settings=uq.Settings(max_steps=400))
    (path,) = fit.save_posteriors(tmp_path)
    idata = az.from_netcdf(path)
    assert {"posterior", "log_likelihood", "posterior_predictive", "observed_data"} <= set(
        idata.groups()
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ArviZ's own notes on the number of chains
        loo = az.loo(idata, var_name="force_N")
        axes = az.plot_ppc(idata, var_names=["force_N"], num_pp_samples=20)
    assert np.isfinite(loo.elpd_loo) and np.size(axes) >= 1

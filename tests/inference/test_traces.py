"""Every "compiles once" claim, checked by counting JAX's compiled programs (the cache size of
each jitted function, as chex.assert_max_traces does): a second fit of the same shape, more
draws, other diagnose candidates or other tests of a campaign must not compile again."""

from __future__ import annotations

import numpy as np

import uq
from uq._inference import collapsed as C
from uq._inference import linear as L

SMALL = uq.Layout(pressures_bar=(2.0, 5.0, 8.0), step_m=0.01)
QUICK = uq.Settings(n_walkers=8, min_steps=20, max_steps=20, chunk=20)  # compiling is the point


def _sizes(*fns) -> list[int]:
    return [f._cache_size() for f in fns]


def test_map_rows_compiles_one_program_whatever_the_number_of_rows():
    """Rows are padded to whole chunks, so 5, 700 and 3000 rows share the program of one chunk."""
    from uq._inference.linear import map_rows

    before = L._map_rows._cache_size()
    for n in (5, 700, 3000):
        out = map_rows(_square, (np.arange(n, dtype=float),))
        assert out.shape == (n,) and out[-1] == (n - 1) ** 2
    assert L._map_rows._cache_size() - before == 1


def _square(x):
    return x * x


def test_a_campaigns_tests_and_a_second_fit_compile_nothing_new():
    """fit_campaign samples all tests of one length with one vmapped log-probability; a second
    campaign of the same shape (other seed, other readings) compiles nothing. The sampler's
    starts, moves and first step and the Laplace curvature at the MAP all run that one program
    (the rows padded to one block), so the campaign adds one log-probability program."""
    fns = (C._log_prob_problems, C._bfgs, L._map_rows)
    before = C._log_prob_problems._cache_size()
    uq.fit_campaign(uq.simulate("n50", seed=1, layout=SMALL), seed=1, settings=QUICK)
    first = _sizes(*fns)
    uq.fit_campaign(uq.simulate("n50", seed=2, layout=SMALL), seed=2, settings=QUICK)
    assert _sizes(*fns) == first
    # three tests, one log-probability program (their lengths are equal), one shape of rows
    assert first[0] - before <= 1


def test_diagnose_candidates_share_one_compilation():
    """The candidate models differ in which mechanisms and magnitudes are on: arrays, not shapes,
    so every candidate's MAP and Laplace curvature use the programs the first one compiled."""
    from uq._diagnose import engine as D
    from uq._models import diagnose as M

    d, _ = M.prepare(uq.simulate("n50-traditional", seed=3, layout=SMALL))
    D.Fit((), 3, d, 1, n_draws=50)
    first = _sizes(C._bfgs, L._map_rows)
    for names in (("force_offset",), ("hysteresis", "volume_excess"), M.MECHS):
        D.Fit(names, 3, d, 2, n_draws=50)
    assert _sizes(C._bfgs, L._map_rows) == first

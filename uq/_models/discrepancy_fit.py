"""The fitted surface with a discrepancy in pressure: its force, areas and blocks on fixed draws.

The model (uq._models.discrepancy) knows the deviations of each tested pressure's cubic from the
smooth surface; between tested pressures each posterior draw carries its Gaussian process in p_u
(uq._models.discrepancy_gp) with its own amplitudes and length scale:

* at the tested pressures the deviations are the draw's (from its exact coefficient draw);
* on a fixed grid of virtual pressures (``GRID_STEP_BAR`` apart over the tested range) each draw's
  process is drawn once, jointly, given its values at the tested pressures: exact, because the
  virtual pressures carry no readings; the standard normals come from the fit's seed and the
  draw's index, so every call (and every thinned view, ``on_draws``) sees the same curves;
* between neighbouring nodes (tested or virtual) the draw's conditional mean given those two
  nodes. What it neglects is the process's conditional sd between the nodes: at most
  ``interpolation_sd(step / l)`` of the amplitude, 5 % for l = 0.5 bar at 0.1-bar nodes (the
  length scale's prior puts 14 % of its mass below 0.5 bar; data/n50's posterior 1 %).

So a draw's force at 801 pressures is one smooth curve in p_u, as ``uq margin`` needs (it looks for
where each draw's force crosses the load).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from uq._inference.convergence import CLI_ADVICE
from uq._inference.summary import band, estimate
from uq._io.errors import InputError
from uq._models import discrepancy_gp as gp
from uq._models import surface
from uq._models.fitted import Block
from uq._models.pair import refuse_extrapolation
from uq._physics.quantities import BAR_PA

MAX_DRAWS = 4000
LEVEL = 0.90
#: rows of draws whose grid values are computed at once (memory: chunk x nodes^2 floats)
GRID_CHUNK = 256
#: the seed stream of the virtual pressures' normals (with the fit's seed)
GRID_STREAM = 29


@dataclass(eq=False, frozen=True, repr=False)
class DiscrepancyFit:
    """The posterior of the surface with a discrepancy in pressure, on a fixed set of draws.

    ``posterior``: the driver's :class:`uq._inference.collapsed.Posterior` (theta: noise logs,
    log a_F, [log a_V,] log l; beta: the surface's standardised coefficients, then z);
    ``data``: the model's arrays (uq._models.discrepancy.DevData or ForceDevData);
    ``max_draws``: the fixed draws are the chains flattened and thinned evenly to at most this."""

    recordings: object
    posterior: object
    stand: object
    orders: surface.Orders
    geometry: surface.Geometry
    data: object
    seed: int = 0
    max_draws: int | None = MAX_DRAWS
    selection: tuple = ()

    name = "discrepancy"
    words = "the surface with a discrepancy in pressure"
    model_name = words
    has_dvdp = False

    # ---- what the protocol names
    @property
    def label(self) -> str:
        return f"surface with a discrepancy in pressure ({self.surface_label}; Matern 3/2 in p_u)"

    @property
    def surface_label(self) -> str:
        return surface.force_label(self.orders) if self.force_only else self.orders.label

    @property
    def force_only(self) -> bool:
        return not self.recordings.has_piston

    @property
    def has_volume(self) -> bool:
        return not self.force_only

    @property
    def omitted_reason(self) -> str | None:
        return surface.volume_omitted_reason(self.recordings)

    @property
    def provenance(self) -> dict:
        return {"recordings_path": str(self.recordings.path), "seed": self.seed}

    @property
    def tested_pressures_bar(self) -> np.ndarray:
        return np.asarray(self.data.p_bar, float)

    @property
    def pressure_range_bar(self) -> tuple[float, float]:
        p = self.tested_pressures_bar
        return float(p.min()), float(p.max())

    @property
    def height_range_m(self) -> tuple[float, float]:
        return self.recordings.height_range_m

    @property
    def convergence(self):
        return self.posterior.convergence

    @property
    def idata(self):
        return self.posterior.idata

    @property
    def loglik_loo(self):
        return self.posterior.loglik_loo

    @property
    def n_draws(self) -> int:
        return int(self.rows.size)

    def check_range(self, height_m, p_bar, param: str | None = None) -> None:
        refuse_extrapolation(
            height_m, p_bar, self.height_range_m, self.pressure_range_bar, param, self.words
        )

    def on_draws(self, n: int) -> DiscrepancyFit:
        """The same model on at most ``n`` of its draws, thinned evenly from all of them (each
        draw keeps its curves between tested pressures)."""
        return dataclasses.replace(self, max_draws=min(int(n), self.max_draws or int(n)))

    def __repr__(self) -> str:
        state = "converged" if self.convergence.converged else "NOT converged"
        return (
            f"DiscrepancyFit({self.label}; {len(self.recordings.tests)} tests, "
            f"{self.recordings.n_points} readings, {self.posterior.beta.shape[-1]} coefficients, "
            f"{self.n_draws} draws, {state})"
        )

    # ---- the fixed draws
    @functools.cached_property
    def rows(self) -> np.ndarray:
        """Indices of the fixed draws among the flattened chains."""
        n = int(np.prod(self.posterior.theta.shape[:2]))
        step = 1 if not self.max_draws or n <= self.max_draws else int(np.ceil(n / self.max_draws))
        return np.arange(0, n, step)

    @functools.cached_property
    def theta(self) -> np.ndarray:
        th = self.posterior.theta
        return th.reshape(-1, th.shape[-1])[self.rows]

    @functools.cached_property
    def beta(self) -> np.ndarray:
        b = self.posterior.beta
        return b.reshape(-1, b.shape[-1])[self.rows]

    @property
    def n_surface(self) -> int:
        return int(self.data.A.shape[2])

    @property
    def n_k(self) -> int:
        return int(self.data.s.shape[0])

    @property
    def n_channels(self) -> int:
        return int(self.data.D.shape[2])

    @functools.cached_property
    def hyper(self) -> dict:
        """The draws' amplitudes (S, n_blocks) m^2 and length scales (S,) bar."""
        nb = self.n_channels // self.n_k
        nat = np.exp(self.theta[:, -(nb + 1) :])
        return {"amplitude": nat[:, :nb], "length": nat[:, -1]}

    @functools.cached_property
    def channel_scale(self) -> np.ndarray:
        """a s_k of every channel (delta's n_k, then eps's), (S, n_c)."""
        s = np.asarray(self.data.s, float)
        return np.concatenate([a[:, None] * s[None, :] for a in self.hyper["amplitude"].T], axis=1)

    @functools.cached_property
    def surface_view(self) -> surface.SurfaceFit:
        """The smooth surface of the same draws (its coefficients alone)."""
        post = dataclasses.replace(self.posterior, beta=self.posterior.beta[..., : self.n_surface])
        return surface.SurfaceFit(self.recordings, post, self.stand, self.orders, self.geometry)

    @property
    def surface_beta(self) -> np.ndarray:
        return self.beta[:, : self.n_surface]

    @functools.cached_property
    def tested_deviations(self) -> np.ndarray:
        """The deviations at the tested pressures, (S, T, n_c) m^2: a s_k chol(R(l)) z."""
        T = self.tested_pressures_bar.size
        z = self.beta[:, self.n_surface :].reshape(-1, self.n_channels, T)
        R = gp.matern32(
            self.tested_pressures_bar[:, None] - self.tested_pressures_bar[None, :],
            self.hyper["length"][:, None, None],
        ) + gp.JITTER * np.eye(T)
        Lr = np.linalg.cholesky(R)
        return np.einsum("sij,scj->sic", Lr, z) * self.channel_scale[:, None, :]

    @functools.cached_property
    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """(node pressures (N,) ascending, deviations there (S, N, n_c)): the tested pressures and
        the virtual ones between them."""
        tested = self.tested_pressures_bar
        grid = gp.grid_nodes(tested)
        S, G, c = self.rows.size, grid.size, self.n_channels
        rng = np.random.default_rng((self.seed, GRID_STREAM))
        n_all = int(np.prod(self.posterior.theta.shape[:2]))
        xi = rng.standard_normal((n_all, G, c))[self.rows]
        vg = np.empty((S, G, c))
        for a in range(0, S, GRID_CHUNK):
            b = slice(a, a + GRID_CHUNK)
            vg[b] = gp.draw_on_grid(
                self.tested_deviations[b],
                self.channel_scale[b],
                self.hyper["length"][b],
                tested,
                grid,
                xi[b],
            )
        allp = np.concatenate([tested, grid])
        order = np.argsort(allp, kind="stable")
        return allp[order], np.concatenate([self.tested_deviations, vg], axis=1)[:, order]

    def deviation_draws(self, height_m, p_bar, *, volume: bool = False, check: bool = True):
        """The deviation of the pressure area (``volume`` True: of the volume-derived area,
        delta + eps) from the surface's, m^2, (S, *shape)."""
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        shape, t, p = h.shape, self.geometry.t(h.ravel()), p.ravel()
        nodes, values = self.nodes
        if nodes.size == 1:
            i, w = np.zeros(p.size, int), np.ones((self.rows.size, p.size, 2)) * [1.0, 0.0]
            values = np.concatenate([values, values], axis=1)
        else:
            i, w = gp.two_point_weights(p, nodes, self.hyper["length"])
        out = np.zeros((self.rows.size, p.size))
        for k in range(self.n_k):
            series = values[:, :, k]
            if volume:
                series = series + values[:, :, self.n_k + k]
            out += (w[..., 0] * series[:, i] + w[..., 1] * series[:, i + 1]) * t**k
        return out.reshape(-1, *shape)

    # ---- the quantities
    def _p_pa(self, height_m, p_bar):
        shape = np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        return np.broadcast_to(np.asarray(p_bar, float), shape) * BAR_PA

    def force_draws(self, height_m, p_bar, *, check: bool = True):
        """The mean force P(x, p_u) (reading noise excluded), N: the surface's plus p_u delta."""
        if check:
            self.check_range(height_m, p_bar)
        base = self.surface_view.force_draws(height_m, p_bar, check=False, beta=self.surface_beta)
        dev = self.deviation_draws(height_m, p_bar, check=False)
        return base + self._p_pa(height_m, p_bar) * dev

    def feff_draws(self, height_m, p_bar, *, check: bool = True):
        """The paper's effective area F_eff = P / p_u (eq. 1) of the mean force, m^2."""
        return self.force_draws(height_m, p_bar, check=check) / self._p_pa(height_m, p_bar)

    def pressure_area_draws(self, height_m, p_bar, *, check: bool = True):
        """F_p + delta, m^2: the pressure area with its deviation."""
        base = self.surface_view.pressure_area_draws(
            height_m, p_bar, check=check, beta=self.surface_beta
        )
        return base + self.deviation_draws(height_m, p_bar, check=False)

    def volume_area_draws(self, height_m, p_bar, *, check: bool = True):
        """The volume-derived area dV/dx = F_p + D + delta + eps, m^2 (eq. 1's second formula)."""
        if self.force_only:
            raise InputError(self.omitted_reason)
        base = self.surface_view.volume_area_draws(
            height_m, p_bar, check=check, beta=self.surface_beta
        )
        return base + self.deviation_draws(height_m, p_bar, volume=True, check=False)

    def volume_pressure_draws(self, height_m, p_bar, *, check: bool = True):
        raise InputError(f"{self.label} has no dV/dp_u of its own (isobaric tests do not give it)")

    def bands(self, height_m, p_bar, level: float = LEVEL) -> dict:
        """Pointwise bands of the force, F_eff and the pressure area (refuses extrapolation)."""
        out = {}
        for name, fn in (
            ("pressure_area_m2", self.pressure_area_draws),
            ("feff_m2", self.feff_draws),
            ("force_N", self.force_draws),
        ):
            m, lo, hi = band(fn(height_m, p_bar), axis=0, level=level)
            out[name] = {"mean": m, "lower": lo, "upper": hi}
        return out

    # ---- blocks and the JSON document
    def blocks(self) -> dict[str, Block]:
        """The surface's blocks and the deviations at the tested pressures, physical units."""
        c, e, d, r = self.surface_view.blocks(self.surface_beta)
        o = self.orders
        out = {
            "pressure_area_m2": Block(
                tuple(f"c_{k}{lq}" for k in range(o.K + 1) for lq in range(o.Lp + 1)),
                c,
                "m^2",
                "F_p = sum c_kl t^k q^l",
            ),
            "casing_N": Block(tuple(f"e_{m}" for m in range(o.Ke + 1)), e, "N", "E = sum e_m t^m"),
        }
        if not self.force_only:
            out["volume_excess_m2"] = Block(
                tuple(f"d_{k}{lq}" for k in range(o.Dk + 1) for lq in range(o.Dl + 1)),
                d,
                "m^2",
                "D = sum d_kl t^k q^l",
            )
            out["piston_reference_m"] = Block(
                tuple(f"r_{p:g}bar" for p in self.tested_pressures_bar),
                r,
                "m",
                "one piston reference per test",
            )
        dev = self.tested_deviations
        for j, (name, basis) in enumerate(
            (
                ("pressure_area_deviation_m2", "F_p + sum_k delta_k t^k at each tested pressure"),
                ("volume_area_deviation_m2", "-dV/dx gains sum_k (delta_k + eps_k) t^k"),
            )[: self.n_channels // self.n_k]
        ):
            sl = slice(j * self.n_k, (j + 1) * self.n_k)
            names = tuple(
                f"{'delta' if j == 0 else 'eps'}_{k}_{p:g}bar"
                for p in self.tested_pressures_bar
                for k in range(self.n_k)
            )
            out[name] = Block(names, dev[:, :, sl].reshape(dev.shape[0], -1), "m^2", basis)
        return out

    def to_json(self, comparison: dict | None = None, advice: str = CLI_ADVICE) -> dict:
        """The model's JSON document (``uq surface --model discrepancy --json``)."""
        return summary(self, comparison, advice)


def hyper_names(fit: DiscrepancyFit) -> tuple[str, ...]:
    return ("a_F_m2", "length_bar") if fit.force_only else ("a_F_m2", "a_V_m2", "length_bar")


def summary(fit: DiscrepancyFit, comparison: dict | None = None, advice: str = CLI_ADVICE) -> dict:
    """The JSON document: the surface's orders, the discrepancy's hyperparameters and its
    deviations at the tested pressures (at x0), force and F_eff at x0, the sampler's verdict."""
    conv = fit.convergence
    r_hat_max, ess_bulk_min = conv.worst()
    post = fit.idata.posterior
    diag = conv.variables
    sampled = {}
    for n in post.data_vars:
        est = estimate(np.asarray(post[n]))
        est |= {k: diag[n][k] for k in ("r_hat", "ess_bulk") if k in diag.get(n, {})}
        sampled[n] = est
    x0 = np.array(fit.geometry.x0_m)
    plo, phi = fit.pressure_range_bar
    tested = fit.tested_pressures_bar
    between = (tested[:-1] + tested[1:]) / 2
    at_x0 = {}
    for pb in sorted({*tested.tolist(), *between.tolist()}):
        at_x0[f"{pb:g}"] = {
            "tested": bool(np.any(np.isclose(pb, tested))),
            "feff_m2": estimate(fit.feff_draws(x0, pb)),
            "force_N": estimate(fit.force_draws(x0, pb)),
            "pressure_area_deviation_m2": estimate(fit.deviation_draws(x0, pb)),
        }
    return {
        "model": fit.name,
        "label": fit.label,
        "x0_m": fit.geometry.x0_m,
        "piston_area_m2": fit.geometry.area_m2,
        "orders": dataclasses.asdict(fit.orders),
        "orders_label": fit.surface_label,
        "discrepancy": {
            "kernel": "Matern 3/2 in p_u (bar)",
            "deviation_degree": fit.n_k - 1,
            "blocks": ["pressure_area_deviation_m2"]
            + ([] if fit.force_only else ["volume_area_deviation_m2"]),
            "priors": {
                "amplitude": f"exponential, P(a > {gp.AMPLITUDE_UPPER_REL:g} x reference area) = "
                f"{gp.AMPLITUDE_TAIL:g}",
                "reference_area_m2": float(
                    -np.log(gp.AMPLITUDE_TAIL) / (gp.AMPLITUDE_UPPER_REL * float(fit.data.rates[0]))
                ),
                "length_bar": f"PC prior of a Matern range, P(l < {gp.LENGTH_LOWER_BAR:g} bar) = "
                f"{gp.LENGTH_TAIL:g}",
            },
            "grid_step_bar": float(np.diff(fit.nodes[0]).max()) if fit.nodes[0].size > 1 else 0.0,
            **{n: sampled[n] for n in hyper_names(fit)},
        },
        "stand": dataclasses.asdict(fit.stand),
        "valid_range": {"height_m": list(fit.height_range_m), "pressure_bar": [plo, phi]},
        "noise": {n: v for n, v in sampled.items() if n not in hyper_names(fit)},
        "at_x0": at_x0,
        "order_selection": list(fit.selection),
        "comparison": comparison,
        "converged": conv.converged,
        "convergence": conv.to_json(advice, variables=False)
        | {"r_hat_max": r_hat_max, "ess_bulk_min": ess_bulk_min},
        "warnings": conv.messages(advice),
    }

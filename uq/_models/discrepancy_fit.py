"""The fitted surface with a discrepancy in pressure: its force, areas and blocks on fixed draws.

The model (uq._models.discrepancy) knows the deviations of each tested pressure's cubic from the
smooth surface; between tested pressures each posterior draw carries its Gaussian process in p_u
(uq._models.discrepancy_gp) with its own amplitudes and length scale:

* at the tested pressures the deviations are the draw's (a coefficient block of the fit, in m^2);
* on a fixed grid of virtual pressures (``GRID_STEP_BAR`` apart over the tested range) each draw's
  process is drawn once, jointly, given its values at the tested pressures: exact, because the
  virtual pressures carry no readings; the standard normals come from the fit's seed and the
  draw's index, so every call (and every thinned view, ``on_draws``, and a saved and loaded model)
  sees the same curves;
* between neighbouring nodes (tested or virtual) the draw's conditional mean given those two
  nodes. What it neglects is the process's conditional sd between the nodes: at most
  ``interpolation_sd(step / l)`` of the amplitude, 5 % for l = 0.5 bar at 0.1-bar nodes.

So a draw's force at 801 pressures is one smooth curve in p_u, as ``uq margin`` needs (it looks for
where each draw's force crosses the load). Everything else (the surface's blocks and columns, the
saved format, the JSON's common parts) is the smooth surface's (uq._models.surface.SurfaceFit),
with the deviations as three more blocks (two without piston readings) and the amplitudes and
length scale among the sampled parameters; a fitted or loaded model evaluates in numpy.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from uq._inference.summary import estimate, thin_rows
from uq._inference.threads import side_by_side
from uq._models import discrepancy_gp as gp
from uq._models.linear_fit import BlockSpec
from uq._models.surface import SurfaceFit, force_label
from uq._models.surface import summary as surface_summary
from uq._physics.quantities import BAR_PA

#: rows of draws whose grid values are computed at once (memory: chunk x nodes^2 floats)
GRID_CHUNK = 64
#: the seed stream of the virtual pressures' normals (with the fit's seed)
GRID_STREAM = 29
#: the deviation blocks in the order of their channels, with and without piston readings
#: (uq._models.discrepancy's module docstring)
BLOCKS = ("delta", "eps", "phi")
FORCE_BLOCKS = ("delta", "phi")
#: per deviation block: its saved name, its amplitude as reported
#: and what it multiplies
BLOCK_INFO = {
    "delta": (
        "pressure_area_deviation_m2",
        "a_F_m2",
        "F_p gains sum_k delta_k t^k at each tested pressure",
    ),
    "eps": ("volume_area_deviation_m2", "a_V_m2", "-dV/dx gains sum_k (delta_k + eps_k) t^k"),
    "phi": (
        "force_deviation_m2",
        "a_P_m2",
        "P gains p_ref sum_k phi_k t^k (p_ref the highest tested overpressure): a force not "
        "proportional to p_u",
    ),
}


def p_ref_pa(tested_bar) -> float:
    """p_ref (Pa), the pressure at which phi's force p_ref sum_k phi_k t^k is an area: the highest
    tested overpressure (phi's amplitude a_P, m^2, is then the sd of a force not proportional to
    p_u as a share of the pressure area at the top of the tested range)."""
    return float(np.max(np.asarray(tested_bar, float))) * BAR_PA


@dataclass(eq=False, frozen=True, repr=False)
class DiscrepancyFit(SurfaceFit):
    """The surface with a discrepancy in pressure, fitted to a campaign (or loaded from a saved
    file), on a fixed set of draws: the surface's coefficients and the deviations at the tested
    pressures as blocks (physical units), the amplitudes and length scale among ``reported``.
    Fitted by ``uq._models.discrepancy.fit_discrepancy``."""

    name = "discrepancy"
    words = "the surface with a discrepancy in pressure"
    likelihood = "uq._models.discrepancy"
    coverage_note = (
        "the default: between tested pressures its band widens by what the data say the smooth "
        "surface misses (docs/discrepancy.md; coverage in reports/between-coverage)"
    )

    @property
    def orders_label(self) -> str:
        base = force_label(self.orders) if self.force_only else self.orders.label
        return f"{base}; Matern 3/2 in p_u"

    # ---- blocks: the surface's, then the deviations at the tested pressures
    @property
    def n_k(self) -> int:
        """Coefficients of a deviation in t (the surface's height degree K, plus one)."""
        return self.orders.K + 1

    @property
    def symbols(self) -> tuple[str, ...]:
        """The deviation blocks, in the order of their channels."""
        return FORCE_BLOCKS if self.force_only else BLOCKS

    @property
    def hyper_names(self) -> tuple[str, ...]:
        """The blocks' amplitudes as reported (m^2), in the same order."""
        return tuple(BLOCK_INFO[s][1] for s in self.symbols)

    @property
    def n_channels(self) -> int:
        return self.n_k * len(self.symbols)

    @property
    def p_ref_pa(self) -> float:
        """p_ref, Pa: phi's force is p_ref sum_k phi_k t^k."""
        return p_ref_pa(self.tested_pressures_bar)

    def surface_layout(self) -> tuple[BlockSpec, ...]:
        return SurfaceFit.block_layout(self)

    def block_layout(self) -> tuple[BlockSpec, ...]:
        blocks = tuple(
            BlockSpec(
                BLOCK_INFO[sym][0],
                tuple(
                    f"{sym}_{k}_{p:g}bar"
                    for p in self.tested_pressures_bar
                    for k in range(self.n_k)
                ),
                1.0,
                "m^2",
                BLOCK_INFO[sym][2],
            )
            for sym in self.symbols
        )
        return (*self.surface_layout(), *blocks)

    @property
    def n_surface(self) -> int:
        return sum(len(b.names) for b in self.surface_layout())

    def _columns(self, x_m, p_bar, c=0.0, e=0.0, d=0.0) -> np.ndarray:
        """The surface's columns, zeros for the deviation blocks (they enter through
        ``deviation_draws``)."""
        cols = super()._columns(x_m, p_bar, c, e, d)
        pad = len(self.tested_pressures_bar) * self.n_channels
        return np.concatenate([cols, np.zeros((cols.shape[0], pad))], axis=1)

    @classmethod
    def from_posterior(cls, posterior, recordings, orders, geometry, stand, *, provenance=None):
        """The fit from the driver's posterior: the surface's standardised coefficients times their
        scales, and the deviations at the tested pressures a s_k chol(R(l)) z of every draw."""
        shell = cls.shell(orders, geometry, recordings.pressures_bar)
        scales = np.concatenate([np.full(len(b.names), b.scale) for b in shell.surface_layout()])
        ks = scales.size
        beta = np.asarray(posterior.beta)
        C, D, K = beta.shape
        reported = {n: np.asarray(v) for n, v in posterior.reported.items()}
        amps = [reported[n].reshape(-1) for n in shell.hyper_names]
        z = beta[..., ks:].reshape(C * D, shell.n_channels, -1)
        dev = gp.tested_values(
            z,
            np.concatenate(
                [a[:, None] * np.full(shell.n_k, gp.COEFFICIENT_SCALE) for a in amps], 1
            ),
            reported["length_bar"].reshape(-1),
            shell.tested_pressures_bar,
        )  # (S, T, n_c)
        blocks = [
            dev[:, :, j * shell.n_k : (j + 1) * shell.n_k].reshape(C * D, -1)
            for j in range(len(amps))
        ]
        coefficients = np.concatenate(
            [beta[..., :ks] * scales, np.concatenate(blocks, axis=1).reshape(C, D, -1)], axis=-1
        )
        return shell.fitted(coefficients, posterior, recordings, stand, provenance)

    # ---- the draws between tested pressures
    @functools.cached_property
    def rows(self) -> np.ndarray:
        """Indices of the fixed draws among all draws (the rule of ``thin_rows``)."""
        return thin_rows(np.arange(int(np.prod(self.coefficients.shape[:2]))), self.max_draws)

    @functools.cached_property
    def hyper(self) -> dict:
        """The fixed draws' amplitudes (S, n_blocks) m^2 and length scales (S,) bar."""
        amps = np.stack(
            [np.asarray(self.reported[n], float).reshape(-1)[self.rows] for n in self.hyper_names],
            1,
        )
        return {
            "amplitude": amps,
            "length": np.asarray(self.reported["length_bar"], float).reshape(-1)[self.rows],
        }

    @functools.cached_property
    def channel_scale(self) -> np.ndarray:
        """a s_k of every channel (block after block, n_k each), (S, n_c)."""
        return np.repeat(self.hyper["amplitude"], self.n_k, axis=1) * gp.COEFFICIENT_SCALE

    @functools.cached_property
    def tested_deviations(self) -> np.ndarray:
        """The deviations at the tested pressures on the fixed draws, (S, T, n_c) m^2."""
        dev = self.coef[:, self.n_surface :]
        T = len(self.tested_pressures_bar)
        per = dev.reshape(dev.shape[0], -1, T, self.n_k)  # (S, block, T, k)
        return np.concatenate([per[:, j] for j in range(per.shape[1])], axis=2)

    @functools.cached_property
    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """(node pressures (N,) ascending, deviations there (n_c, S, N): channel by channel): the
        tested pressures and the virtual ones between them."""
        tested = np.asarray(self.tested_pressures_bar, float)
        grid = gp.grid_nodes(tested)
        S, G, c = self.rows.size, grid.size, self.n_channels
        seed = int(self.provenance.get("seed") or 0)
        rng = np.random.default_rng((seed, GRID_STREAM))
        n_all = int(np.prod(self.coefficients.shape[:2]))
        xi = rng.standard_normal((n_all, G, c))[self.rows]
        dev, scale, length = self.tested_deviations, self.channel_scale, self.hyper["length"]

        def chunk(a):
            b = slice(a, a + GRID_CHUNK)
            return gp.draw_on_grid(dev[b], scale[b], length[b], tested, grid, xi[b])

        # draws apart: chunks side by side (numpy's linear algebra releases the interpreter)
        vg = np.concatenate(side_by_side(chunk, range(0, S, GRID_CHUNK)))
        allp = np.concatenate([tested, grid])
        order = np.argsort(allp, kind="stable")
        values = np.concatenate([self.tested_deviations, vg], axis=1)[:, order]
        return allp[order], np.ascontiguousarray(values.transpose(2, 0, 1))

    def deviation_draws(
        self, height_m, p_bar, blocks=("delta",), *, factors=None, check: bool = True
    ) -> np.ndarray:
        """The sum of the deviation ``blocks`` at the points, m^2, (S, *shape), each times its
        factor in ``factors`` (symbol -> a number, or a function of pressures in bar, (n,) ->
        (n,); default 1): ("delta",) the pressure area's, ("delta", "eps") the volume-derived area's, delta
        times p_u and phi times p_ref the force's. Only the blocks asked for are computed. A
        deviation is a polynomial in t whose coefficients (the two-node mean of the nodes' draws)
        depend on the pressure alone: they are made once per distinct pressure and, where the
        points are a grid of their distinct heights and pressures, the polynomials evaluated on
        that grid."""
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        shape, n_k = h.shape, self.n_k
        pu, at_p = np.unique(p.ravel(), return_inverse=True)
        hu, at_h = np.unique(h.ravel(), return_inverse=True)
        nodes, values = self.nodes
        if nodes.size == 1:
            i, w = np.zeros(pu.size, int), np.ones((self.rows.size, pu.size, 2)) * [1.0, 0.0]
            values = np.concatenate([values, values], axis=2)
        else:
            i, w = gp.two_point_weights(pu, nodes, self.hyper["length"])
        # on the grid of the distinct heights and pressures where the points are one (or nearly),
        # then looked up; else point by point. One coefficient at a time: temporaries of (draws x
        # distinct pressures), the output's size at most
        on_grid = pu.size * hu.size <= 2 * h.size
        t = self.geometry.t(hu if on_grid else h.ravel())
        at_p, at_h = at_p.reshape(-1), at_h.reshape(-1)
        out = np.zeros((self.rows.size, pu.size, hu.size) if on_grid else (self.rows.size, h.size))
        w0, w1 = np.ascontiguousarray(w[..., 0]), np.ascontiguousarray(w[..., 1])
        for sym in blocks:
            scale = (factors or {}).get(sym)
            scale = scale(pu) if callable(scale) else scale
            for k, series in enumerate(values[self.symbols.index(sym) * n_k :][:n_k]):
                c = w0 * series[:, i] + w1 * series[:, i + 1]  # (S, distinct pressures)
                if scale is not None:
                    c *= scale
                out += c[:, :, None] * t**k if on_grid else c[:, at_p] * t**k
        if on_grid:
            out = out.reshape(out.shape[0], -1)[:, at_p * hu.size + at_h]
        return out.reshape(-1, *shape)

    # ---- the quantities: the surface's plus the deviations
    def force_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """The mean force P(x, p_u) (reading noise excluded), N: the surface's plus p_u delta plus
        p_ref phi."""
        base = super().force_draws(height_m, p_bar, check=check)
        at = {"delta": lambda p: p * BAR_PA, "phi": self.p_ref_pa}
        return base + self.deviation_draws(height_m, p_bar, tuple(at), factors=at, check=False)

    def pressure_area_draws(self, height_m, p_bar, *, check=True):
        """F_p + delta, m^2: the pressure area with its deviation."""
        base = super().pressure_area_draws(height_m, p_bar, check=check)
        return base + self.deviation_draws(height_m, p_bar, check=False)

    def volume_area_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """The volume-derived area dV/dx = F_p + D + delta + eps, m^2 (eq. 1's second formula)."""
        base = super().volume_area_draws(height_m, p_bar, check=check)
        return base + self.deviation_draws(height_m, p_bar, ("delta", "eps"), check=False)

    def volume_excess_draws(self, height_m, p_bar, *, check=True):
        """D + eps = -dV/dx - (F_p + delta), m^2."""
        base = super().volume_excess_draws(height_m, p_bar, check=check)
        return base + self.deviation_draws(height_m, p_bar, ("eps",), check=False)

    def spread_draws(self, height_m, p_bar, *, check=True):
        """p_u (-dV/dx) - P = p_u (D + eps) - E - p_ref phi, N."""
        base = super().spread_draws(height_m, p_bar, check=check)
        at = {"eps": lambda p: p * BAR_PA, "phi": -self.p_ref_pa}
        return base + self.deviation_draws(height_m, p_bar, tuple(at), factors=at, check=False)

    # ---- the JSON document
    def fitted_document(self, comparison: dict | None, advice: str) -> dict:
        """The surface's document (``uq surface --json``) with the discrepancy: its kernel, priors,
        sampled amplitudes and length scale, and its deviation at x0 at and between the tested
        pressures."""
        doc = surface_summary(self, comparison, advice)
        doc["label"] = self.label
        doc["discrepancy"] = discrepancy_summary(self)
        return doc


def discrepancy_summary(fit: DiscrepancyFit) -> dict:
    names = fit.hyper_names
    tested = np.asarray(fit.tested_pressures_bar, float)
    between = (tested[:-1] + tested[1:]) / 2
    some = fit.on_draws(2000)
    x0 = np.array(fit.x0_m)
    at_x0 = {
        f"{pb:g}": {
            "tested": bool(np.any(np.isclose(pb, tested))),
            "pressure_area_deviation_m2": estimate(some.deviation_draws(x0, pb)),
            "force_deviation_N": estimate(some.p_ref_pa * some.deviation_draws(x0, pb, ("phi",))),
            "force_N": estimate(some.force_draws(x0, pb)),
        }
        for pb in sorted({*tested.tolist(), *between.tolist()})
    }
    return {
        "kernel": "Matern 3/2 in p_u (bar)",
        "deviation_degree": fit.n_k - 1,
        "blocks": [BLOCK_INFO[s][0] for s in fit.symbols],
        "p_ref_bar": fit.p_ref_pa / BAR_PA,
        "priors": {
            "amplitude": f"exponential, P(a > {gp.AMPLITUDE_UPPER_REL:g} x reference area) = "
            f"{gp.AMPLITUDE_TAIL:g} (reference area: the median pressure area of a least-squares fit)",
            "length_bar": f"PC prior of a Matern range, P(l < {gp.LENGTH_LOWER_BAR:g} bar) = "
            f"{gp.LENGTH_TAIL:g}",
        },
        "grid_step_bar": float(np.diff(fit.nodes[0]).max()) if fit.nodes[0].size > 1 else 0.0,
        **fit.noise_summary(names + ("length_bar",)),
        "at_x0": at_x0,
    }

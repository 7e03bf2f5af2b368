"""LIN planning: the joint path of a straight TCP line and its limits along the path.

A KRC plans a CP motion so that no axis exceeds its limits: near a singularity the path velocity
drops instead of an axis overspeeding (KSS ``$CP_VEL_TYPE = #VAR_ALL``), and a line that really
passes through a singularity is refused. The emulator does the same in two stages, both
generators that yield after a bounded slice of work, so the advance run can spread a long LIN
over several IPO cycles instead of holding the event loop:

1. :func:`~.joint_path.joint_path` (in :mod:`.joint_path`) samples the line every ``LIN_STEP`` mm/deg and solves it with IK in
   batches, in the start's configuration (the S bits: a continuous motion cannot change them
   without passing a singularity), each solution unwrapped to the multi-turn value nearest its
   neighbour. Intervals where an axis moves more than ``MAX_STEP`` degrees are bisected until it
   does not. An interval shorter than ``MIN_STEP`` that still jumps is a discontinuity of the
   joint path: the line crosses a singularity, and the LIN is refused.
2. :class:`PathLimits` turns the nodes into the bounds of the path parameter ``s``: a cap on
   ``ṡ`` from ``$VEL.CP``/``ORI1`` and every axis speed (the joint path is linear between nodes,
   so capping both ends of an interval bounds the whole interval), and bounds on ``s̈`` from
   ``$ACC.CP``/``ORI1`` and every axis acceleration ``q'·s̈ + q''·ṡ²``, which depend on ``ṡ²``
   through the path's curvature. Its :meth:`~PathLimits.backward` / :meth:`~PathLimits.forward`
   passes integrate the fastest profile within them in the phase plane (time-optimal path
   parameterisation by numerical integration).

We integrate the phase plane ourselves instead of calling a TOPP library (toppra): the passes
must yield every few hundred nodes to keep the event loop free, and they work on the exact IK
nodes rather than a spline through them, which would overshoot at a singular wrist swing.
"""

from __future__ import annotations

import math
from collections.abc import Generator

import numpy as np

from pyopenshowvar.kinematics import RobotModel

from .joint_path import (
    LinGeometry,
    PathRefused,
    singularity,
)
from .profiles import Curve, FloatArray, pl_min

__all__ = ["PathLimits"]

#: Nodes per slice of the phase-plane passes.
PASS_CHUNK = 40
#: Fractions of the axis limits the planner uses: the IK path bends slightly between nodes.
SPEED_MARGIN = 0.99
ACCEL_MARGIN = 0.95
_BIG = 1e30


def _pair_cap(
    alp: FloatArray, beta_lo: FloatArray, gam: FloatArray, beta_hi: FloatArray
) -> FloatArray:
    """The largest ṡ² per node at which every lower bound ``α_j + β_j·ṡ²`` stays below every
    upper bound ``γ_m + β_m·ṡ²``: ``(β_j − β_m)·ṡ² ≤ γ_m − α_j`` for each pair."""
    db = beta_lo[:, :, None] - beta_hi[:, None, :]
    room = gam[:, None, :] - alp[:, :, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        pair = np.where(db > 0, room / db, np.inf)
    return np.asarray(np.min(pair, axis=(1, 2)))


class PathLimits:
    """Speed cap and acceleration bounds of the path parameter at each node of a LIN.

    ``v_cart``/``a_cart`` are (mm/s, deg/s) and (mm/s², deg/s²) of ``$VEL``/``$ACC`` (CP and
    ORI1); ``v_axis``/``a_axis`` the axis limits (deg/s, deg/s²). At node ``k`` every limit
    reads ``α_j + β_j·ṡ² ≤ s̈ ≤ γ_j + β_j·ṡ²``, and ``xcap[k]`` is the largest ``ṡ²`` at which
    the speed limits hold and these bounds still leave room for some ``s̈``.
    """

    def __init__(
        self,
        model: RobotModel,
        s: FloatArray,
        q: FloatArray,
        geo: LinGeometry,
        v_cart: tuple[float, float],
        a_cart: tuple[float, float],
        v_axis: FloatArray,
        a_axis: FloatArray,
    ) -> None:
        self.model, self.s, self.q = model, s, q
        span = np.diff(s)
        self.chord = np.diff(q, axis=0) / span[:, None]  # deg per unit s, per interval
        qp = np.empty_like(q)
        qp[0], qp[-1] = self.chord[0], self.chord[-1]
        w0, w1 = span[:-1, None], span[1:, None]
        qp[1:-1] = (self.chord[:-1] * w1 + self.chord[1:] * w0) / (w0 + w1)
        qpp = np.zeros_like(q)
        lo = hi = qpp
        if len(span) > 1:
            qpp[1:-1] = (self.chord[1:] - self.chord[:-1]) / (0.5 * (w0 + w1))
            qpp[0], qpp[-1] = qpp[1], qpp[-2]
            # the curvature changes fast near a singularity: bound each node by its neighbours'
            near = np.stack([np.roll(qpp, 1, axis=0), qpp, np.roll(qpp, -1, axis=0)])
            near[0, 0], near[2, -1] = qpp[0], qpp[-1]
            lo, hi = near.min(axis=0), near.max(axis=0)
            pick = np.argmax(np.abs(near), axis=0)
            qpp = np.take_along_axis(near, pick[None], axis=0)[0]
        self.qp, self.qpp = qp, qpp

        def per_unit(limits: tuple[float, float]) -> float:
            out = math.inf
            for dist, lim in zip((geo.length, geo.angle), limits, strict=True):
                if dist > 1e-9:
                    out = min(out, lim / dist)
            return out

        v_cp, a_cp = per_unit(v_cart), per_unit(a_cart)
        # speed: both chords next to a node cap it
        with np.errstate(divide="ignore"):
            v_int = np.min(v_axis * SPEED_MARGIN / np.abs(self.chord), axis=1)
        v_node = np.minimum(np.append(v_int, v_int[-1]), np.insert(v_int, 0, v_int[0]))
        xcap = np.minimum(v_node, v_cp) ** 2
        # acceleration rows: |q'·s̈ + q''·ṡ²| ≤ a per axis, for q' between the chords on either
        # side of the node and q'' between its neighbours' extremes (the nodes only sample a
        # path whose slope and curvature vary in between: near a singularity the two terms
        # nearly cancel, and one sample of each would under- or over-state either); the
        # constraint is linear in (q', q''), so the four corners bound the whole range
        self.a_limit = a_axis
        amax = self.a_axis = a_axis * ACCEL_MARGIN
        slopes = (np.vstack([self.chord[:1], self.chord]), np.vstack([self.chord, self.chord[-1:]]))
        gams, betas, stills = [], [], []
        for slope in slopes:
            for curve in (lo, hi):
                moving = np.abs(slope) > 1e-9
                with np.errstate(divide="ignore", invalid="ignore"):
                    gams.append(np.where(moving, amax / np.abs(slope), _BIG))
                    betas.append(np.where(moving, -curve / slope, 0.0))
                    stills.append(
                        np.where(~moving & (np.abs(curve) > 0), amax / np.abs(curve), np.inf)
                    )
        gam, beta, still = np.hstack(gams), np.hstack(betas), np.hstack(stills)
        #: the axis rows' γ (the first columns) and their speed caps, for :meth:`tighten`
        self._axis_gam, self._still = gam, np.min(still, axis=1)
        self._speed_cap, self._extra_cap = xcap, np.full(len(s), np.inf)
        a_s = min(a_cp, _BIG)
        gam = np.hstack([gam, np.full((len(s), 1), a_s)])
        beta = np.hstack([beta, np.zeros((len(s), 1))])
        self._xcap0 = np.minimum(xcap, self._still)
        self._rows = (-gam, beta, gam)
        self._finish()

    def constrain(
        self, alp: FloatArray, beta: FloatArray, gam: FloatArray, cap: FloatArray
    ) -> None:
        """Add rows ``α + β·ṡ² ≤ s̈ ≤ γ + β·ṡ²`` (``(nodes, k)`` arrays) and a cap on ṡ² per
        node (the motors' torque, :meth:`.dynamics.ControllerDynamics.path_rows`)."""
        a0, b0, g0 = self._rows
        self._extra_cap = np.minimum(self._extra_cap, cap)
        # only the pairs that involve a new row can lower the cap further
        xcap = np.minimum(self.xcap, cap)
        for lo_rows, hi_rows in (
            ((alp, beta), (g0, b0)),
            ((a0, b0), (gam, beta)),
            ((alp, beta), (gam, beta)),
        ):
            xcap = np.minimum(xcap, _pair_cap(*lo_rows, *hi_rows))
        self._rows = (np.hstack([a0, alp]), np.hstack([b0, beta]), np.hstack([g0, gam]))
        self._set_cap(xcap)

    def tighten(self, factor: FloatArray) -> None:
        """Scale the axis-acceleration rows of each node by ``factor`` (≤ 1, per node, relative
        to the rows first built): where the nodes sample the joint path too coarsely for the
        rows to hold on the set-points (:mod:`.retime`), the profile slows down there."""
        alp, beta, gam = (r.copy() for r in self._rows)
        cols = self._axis_gam.shape[1]
        gam[:, :cols] = self._axis_gam * factor[:, None]
        alp[:, :cols] = -gam[:, :cols]
        self._rows = (alp, beta, gam)
        nodes = np.flatnonzero(factor < 1.0)  # the other nodes' caps stay as they are
        xcap = self.xcap.copy()
        xcap[nodes] = np.minimum.reduce([
            self._speed_cap[nodes],
            self._still[nodes] * factor[nodes],
            self._extra_cap[nodes],
            _pair_cap(alp[nodes], beta[nodes], gam[nodes], beta[nodes]),
        ])  # fmt: skip
        self._set_cap(xcap)

    def _finish(self) -> None:
        alp, beta, gam = self._rows
        self._set_cap(np.minimum(self._xcap0, _pair_cap(alp, beta, gam, beta)))

    def _set_cap(self, xcap: FloatArray) -> None:
        alp, beta, gam = self._rows
        self.xcap = xcap
        self._alp, self._beta, self._gam = alp.tolist(), beta.tolist(), gam.tolist()
        self._s, self._cap = self.s.tolist(), xcap.tolist()

    # --- bounds ---------------------------------------------------------------------------
    def _lo(self, k: int, x: float) -> float:
        return float(max(a + b * x for a, b in zip(self._alp[k], self._beta[k], strict=True)))

    def _hi(self, k: int, x: float) -> float:
        return float(min(g + b * x for g, b in zip(self._gam[k], self._beta[k], strict=True)))

    def xcap_on(self, s0: float, s1: float) -> float:
        """The lowest speed cap (ṡ²) over ``[s0, s1]``."""
        k0 = max(int(np.searchsorted(self.s, s0, side="right")) - 1, 0)
        k1 = int(np.searchsorted(self.s, s1, side="left"))
        return float(np.min(self.xcap[k0 : k1 + 1]))

    def derivatives(self, s: float) -> tuple[FloatArray, FloatArray]:
        """``dq/ds`` and ``d²q/ds²`` (deg) where the path parameter is ``s``."""
        k = min(max(int(np.searchsorted(self.s, s, side="right")) - 1, 0), len(self.chord) - 1)
        return self.chord[k], self.qpp[k]

    # --- phase-plane passes ---------------------------------------------------------------
    def backward(
        self, s_end: float, x_end: float, above: Curve | None = None
    ) -> Generator[None, None, Curve]:
        """Fastest approach to ``(s_end, ṡ² = x_end)`` from earlier nodes, decelerating as hard
        as the bounds allow. With ``above``, stops at the first node where the curve reaches
        ``above`` (from there on ``above`` is the lower one); returns the curve on its span."""
        s_list, cap = self._s, self._cap
        k = int(np.searchsorted(self.s, s_end, side="left")) - 1
        ss, xs = [s_end], [x_end]
        s_next, x_next, k_next = s_end, x_end, min(k + 1, len(s_list) - 1)
        lim_next = max(x_end, cap[k_next])
        count = 0
        while k >= 0:
            d = s_next - s_list[k]
            cand = x_next - 2.0 * d * self._lo(k_next, x_next)
            for a, b in zip(self._alp[k], self._beta[k], strict=True):
                den = 1.0 + 2.0 * d * b
                if den > 0.0:
                    cand = min(cand, (x_next - 2.0 * d * a) / den)
            if cand > cap[k] and x_next < lim_next:
                # the braking line meets the speed cap inside the interval: keep that corner
                f = (lim_next - x_next) / ((lim_next - x_next) + (cand - cap[k]))
                ss.append(s_next - f * d)
                xs.append(x_next + f * (cand - x_next))
            x = max(min(cap[k], cand), 0.0)  # 0: cannot pass here without stopping
            ss.append(s_list[k])
            xs.append(x)
            if above is not None and x >= float(np.interp(s_list[k], *above)):
                break
            s_next, x_next, k_next, lim_next = s_list[k], x, k, cap[k]
            k -= 1
            count += 1
            if count % PASS_CHUNK == 0:
                yield
        return np.array(ss[::-1]), np.array(xs[::-1])

    def forward(self, s_start: float, x_start: float, below: Curve) -> Generator[None, None, Curve]:
        """Fastest profile from ``(s_start, x_start)`` to the end, accelerating as hard as the
        bounds allow but never above ``below`` (the backward curve, which decelerates in time).
        Raises :class:`PathRefused` if the path speed would fall to zero on the way."""
        s_list, cap = self._s, self._cap
        k = int(np.searchsorted(self.s, s_start, side="right"))
        ss, xs = [s_start], [x_start]
        s_prev, x_prev, k_prev = s_start, x_start, max(k - 1, 0)
        limit = np.minimum(np.interp(self.s, *below), self.xcap).tolist()
        lim_prev = max(x_start, min(cap[k_prev], float(np.interp(s_start, *below))))
        count = 0
        while k < len(s_list):
            d = s_list[k] - s_prev
            cand = x_prev + 2.0 * d * self._hi(k_prev, x_prev)
            for g, b in zip(self._gam[k], self._beta[k], strict=True):
                den = 1.0 - 2.0 * d * b
                if den > 0.0:
                    cand = min(cand, (x_prev + 2.0 * d * g) / den)
            if cand > limit[k] and x_prev < lim_prev:
                # the acceleration line meets the limit curve inside the interval
                f = (lim_prev - x_prev) / ((lim_prev - x_prev) + (cand - limit[k]))
                ss.append(s_prev + f * d)
                xs.append(x_prev + f * (cand - x_prev))
            x = min(limit[k], cand)
            if x <= 0.0 and k < len(s_list) - 1:
                where = singularity(self.model, self.q[k])
                raise PathRefused(
                    f"path runs too close to the {where} singularity near {s_list[k]:.0%}: "
                    "its speed would fall to zero"
                )
            ss.append(s_list[k])
            xs.append(max(x, 0.0))
            s_prev, x_prev, k_prev, lim_prev = s_list[k], x, k, limit[k]
            k += 1
            count += 1
            if count % PASS_CHUNK == 0:
                yield
        return np.array(ss), np.array(xs)

    def plan(self) -> Generator[None, None, tuple[Curve, Curve]]:
        """The rest-to-rest profile: ``(profile curve, backward curve)``."""
        bw = yield from self.backward(1.0, 0.0)
        fw = yield from self.forward(0.0, 0.0, bw)
        return pl_min(fw, bw), bw

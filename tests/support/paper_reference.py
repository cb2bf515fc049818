"""A slow, literal second implementation of the paper model, written from the spec alone.

It shares no code with ``planner`` on purpose: the tests compare the two state
by state. Pure Python over nested lists; fine for grids of a few hundred states.
"""

from __future__ import annotations

import heapq
import math

STEPS = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)]  # spec section 2
R = 6371000.0
INF = (math.inf, math.inf)


def sign(x: float) -> int:
    return (x > 0) - (x < 0)


def flow_dir(u, v, lat, dlon, dlat, calm):
    """Spec section 3 for one cell; None for land, -1 for calm, else k."""
    if not (math.isfinite(u) and math.isfinite(v)):
        return None
    dx = R * math.cos(math.radians(lat)) * math.radians(dlon)
    dy = R * math.radians(dlat)
    a = u / dx
    b = v / dy
    if math.hypot(u, v) <= calm or (a == 0 and b == 0):
        return -1
    A, B = abs(a), abs(b)
    if A >= B:
        di, dj = sign(a), (sign(b) if 2 * B >= A else 0)
    else:
        dj, di = sign(b), (sign(a) if 2 * A >= B else 0)
    return STEPS.index((di, dj))


class PaperModel:
    """Spec sections 1 to 7 over a grid given as lists: ``u[l][j][i]``, ``v[l][j][i]``."""

    def __init__(self, u, v, lat, dlon, dlat, costs, lateral=True, calm=0.01):
        self.L, self.ny, self.nx = len(u), len(u[0]), len(u[0][0])
        self.flow = [
            [[flow_dir(u[l][j][i], v[l][j][i], lat[j], dlon, dlat, calm) for i in range(self.nx)] for j in range(self.ny)]
            for l in range(self.L)
        ]
        self.costs = costs  # by action code 0..5
        self.lateral = lateral

    def water(self, l, j, i):
        return 0 <= i < self.nx and 0 <= j < self.ny and self.flow[l][j][i] is not None

    def states(self):
        for l in range(self.L):
            for j in range(self.ny):
                for i in range(self.nx):
                    if self.water(l, j, i):
                        for k in range(8):
                            yield (l, j, i, k)

    def move(self, l, j, i, d, n):
        """Step up to n tiles along d in layer l; stop before land or the edge (spec section 5)."""
        for _ in range(n):
            ni, nj = i + STEPS[d][0], j + STEPS[d][1]
            if not self.water(l, nj, ni):
                break
            i, j = ni, nj
        return j, i

    def outcomes(self, z, a):
        """Set of outcome states, or None if the action is unavailable."""
        l, j, i, k = z
        w = self.flow[l][j][i]
        if a == 2:
            return {(l, j, i, (k + 1) % 8)}
        if a == 3:
            return {(l, j, i, (k - 1) % 8)}
        lt = {0: l, 1: l, 4: l - 1, 5: l + 1}[a]
        if a in (4, 5) and not (0 <= lt < self.L and self.water(lt, j, i)):
            return None
        if w == -1:
            n = 1 if a == 1 else 0
            d = k
        else:
            rho = 45 * min(abs(k - w), 8 - abs(k - w))
            s = rho / 180
            n = 2 if s <= 0.2 else (1 if s <= 0.5 else 0)
            d = k if a == 1 else w
        if n == 0:
            return {(lt, j, i, k)}
        dirs = [d, (d + 1) % 8, (d - 1) % 8] if self.lateral else [d]
        result = set()
        for dd in dirs:
            jj, ii = self.move(lt, j, i, dd, n)
            result.add((lt, jj, ii, k))
        return result

    def goal_states(self, gl, gj, gi, radius):
        return {
            (gl, j, i, k)
            for j in range(self.ny)
            for i in range(self.nx)
            if max(abs(i - gi), abs(j - gj)) <= radius and self.water(gl, j, i)
            for k in range(8)
        }

    def edges(self):
        """Forward graph: state -> list of (action, outcome set)."""
        return {z: [(a, o) for a in range(6) if (o := self.outcomes(z, a)) is not None] for z in self.states()}

    def policy_from_values(self, V, goals, criterion):
        """The tie rule of spec section 7 applied to values V."""
        pol = {}
        edges = self.edges()
        for z in edges:
            if z in goals:
                pol[z] = 6
                continue
            if V[z] == INF:
                pol[z] = 7
                continue
            best = None
            for a, outs in edges[z]:
                vals = [V[o] for o in outs]
                vo = max(vals) if criterion == "robust" else min(vals)
                q = (self.costs[a] + vo[0], 1 + vo[1])
                if q == V[z] and (best is None or (self.costs[a], a) < (self.costs[best], best)):
                    best = a
            pol[z] = best
        return pol


def algorithm1_optimistic(model: PaperModel, goals):
    """The paper's Algorithm 1 taken literally: one forward Dijkstra per start state."""
    edges = model.edges()
    V = {}
    for start in edges:
        if start in goals:
            V[start] = (0, 0)
            continue
        dist = {start: (0, 0)}
        heap = [((0, 0), start)]
        done = set()
        found = INF
        while heap:
            d, z = heapq.heappop(heap)
            if z in done:
                continue
            done.add(z)
            if z in goals:
                found = d
                break
            for a, outs in edges[z]:
                for o in outs:
                    nd = (d[0] + model.costs[a], d[1] + 1)
                    if nd < dist.get(o, INF):
                        dist[o] = nd
                        heapq.heappush(heap, (nd, o))
        V[start] = found
    return V, model.policy_from_values(V, goals, "optimistic")


def value_iteration(model: PaperModel, goals, criterion):
    """Bellman iteration to the least fixed point; exact for positive (cost, 1) steps."""
    edges = model.edges()
    V = {z: ((0, 0) if z in goals else INF) for z in edges}
    changed = True
    while changed:
        changed = False
        for z in edges:
            if z in goals:
                continue
            best = V[z]
            for a, outs in edges[z]:
                vals = [V[o] for o in outs]
                vo = max(vals) if criterion == "robust" else min(vals)
                if vo == INF:
                    continue
                q = (model.costs[a] + vo[0], 1 + vo[1])
                if q < best:
                    best = q
            if best != V[z]:
                V[z] = best
                changed = True
    return V, model.policy_from_values(V, goals, criterion)

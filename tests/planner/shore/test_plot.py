"""The plan pictures (paper Figs. 3, 5, 6): files, pixels, markers, and the demo start state."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from planner.contract.errors import LrauvError
from planner.grid import Grid
from planner.contract.geodesy import BBox
from planner.contract.headings import Direction
from planner.shore.plots import default_start, plot_all, plot_flow_fields, plot_nominal_path, plot_policy
from planner.contract.settings import Goal, PlanSettings
from planner.paper.solve import solve
from planner.paper.transitions import build_transitions
from tests.support import REPO

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def vortex_case(nx: int = 12, ny: int = 9):
    """A Gaussian-like vortex, weaker and shifted at 10 m, with a land block growing with depth."""
    grid = Grid.from_bbox(BBox(west_deg=-118.2, south_deg=33.4, east_deg=-118.0, north_deg=33.55), nx=nx, ny=ny,
                          depths_m=[0.0, 10.0])
    x = (np.arange(nx) - (nx - 1) / 2) / nx * 2
    y = (np.arange(ny) - (ny - 1) / 2) / ny * 2
    X, Y = np.meshgrid(x, y)
    r = np.hypot(X, Y)
    v_theta = 0.4 * r * np.exp(1 - r**2 / 0.5) / np.sqrt(0.5)
    theta = np.arctan2(Y, X)
    u0, v0 = -v_theta * np.sin(theta), v_theta * np.cos(theta)
    u = np.stack([u0, 0.6 * u0 + 0.05])
    v = np.stack([v0, 0.6 * v0])
    land = np.zeros(u.shape, dtype=bool)
    land[:, ny - 3 :, nx - 3 :] = True
    land[1, ny - 4 :, nx - 5 :] = True
    u[land] = np.nan
    v[land] = np.nan
    goal = Goal(lon_deg=float(grid.lon_deg[2]), lat_deg=float(grid.lat_deg[6]), depth_m=0.0, radius_cells=1)
    return grid, u, v, goal


@pytest.fixture(scope="module")
def plan():
    grid, u, v, goal = vortex_case()
    solution = solve(build_transitions(u, v, grid, PlanSettings()), goal)
    return u, v, solution


@pytest.fixture(scope="module")
def pictures(plan, tmp_path_factory):
    u, v, solution = plan
    out = tmp_path_factory.mktemp("plots")
    return out, plot_all(u, v, solution, out)


def read_rgb(path: Path) -> np.ndarray:
    import matplotlib.image

    img = matplotlib.image.imread(path)
    return img[..., :3].astype(np.float64)  # (rows, cols, 3) in 0..1


def red_mask(rgb: np.ndarray) -> np.ndarray:
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (r > 0.75) & (g < 0.25) & (b < 0.25)


def green_mask(rgb: np.ndarray) -> np.ndarray:
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (g > 0.45) & (r < 0.3) & (b < 0.4) & (g - np.maximum(r, b) > 0.2)


def test_plot_all_writes_the_three_pictures(pictures):
    out, paths = pictures
    names = [p.name for p in paths]
    assert names[0] == "flow_fields.png"
    assert names[1] == "policy_k0_l0.png"  # heading E, goal layer by default
    assert names[2] == "nominal_path.png"
    # Written atomically: nothing else (no temporary files) is left in the folder.
    assert sorted(os.listdir(out)) == sorted(names)
    for p in paths:
        assert p.read_bytes()[:8] == PNG_MAGIC, p


@pytest.mark.parametrize("index", [0, 1, 2])
def test_pictures_have_sensible_size_and_content(pictures, index):
    _, paths = pictures
    rgb = read_rgb(paths[index])
    rows, cols, _ = rgb.shape
    assert 600 <= cols <= 3000 and 400 <= rows <= 3000, (paths[index].name, rgb.shape)
    assert rgb.std() > 0.05, "picture is (nearly) blank"
    q = (rgb * 255).round().astype(np.int64)
    colours = np.unique((q[..., 0] << 16) | (q[..., 1] << 8) | q[..., 2])
    assert colours.size > 200, f"{paths[index].name}: only {colours.size} distinct colours"
    assert (rgb.min(axis=2) < 0.95).mean() > 0.08, "picture is almost all white"


def test_nominal_path_draws_red_start_and_green_goal(pictures):
    _, paths = pictures
    rgb = read_rgb(paths[2])
    map_part = rgb[:, : int(0.7 * rgb.shape[1])]  # the legend and summary sit on the right
    assert red_mask(map_part).sum() > 150
    assert green_mask(map_part).sum() > 150


def test_start_marker_follows_the_start(plan, tmp_path):
    """The red marker moves with the start state: east start -> red further right than a west start."""
    _, _, solution = plan
    l, j, i, k = default_start(solution)
    assert i == solution.model.grid.nx - 1  # for this case: the far (east) edge
    west = (l, j, 0, k)
    assert np.isfinite(solution.cost[west])
    east_png = plot_nominal_path(solution, (l, j, i, k), tmp_path / "east.png")
    west_png = plot_nominal_path(solution, west, tmp_path / "west.png")
    centroids = []
    for png in (east_png, west_png):
        rgb = read_rgb(png)
        red = red_mask(rgb[:, : int(0.7 * rgb.shape[1])])
        assert red.sum() > 150
        centroids.append(np.nonzero(red)[1].mean())
    assert centroids[0] > centroids[1] + 200


def test_default_start_is_a_far_reachable_non_goal_state(plan):
    _, _, solution = plan
    l, j, i, k = default_start(solution)
    gc = solution.goal_cells
    assert (l, k) == (gc.l, Direction.E)
    assert solution.model.water[l, j, i]
    assert np.isfinite(solution.cost[l, j, i, k]) and solution.steps[l, j, i, k] > 0
    assert not gc.mask[l, j, i]
    # Farthest (in cells, on this near-square grid) among the reachable east-heading states of the goal layer.
    ok = np.isfinite(solution.cost[l, :, :, k]) & ~gc.mask[l]
    jj, ii = np.nonzero(ok)
    dx_m, dy_m = solution.model.grid.cell_size_m()
    dist = np.hypot((ii - gc.i) * dx_m[jj], (jj - gc.j) * dy_m)
    assert np.hypot((i - gc.i) * dx_m[j], (j - gc.j) * dy_m) == pytest.approx(dist.max())


def test_policy_for_another_heading_and_layer(plan, tmp_path):
    _, _, solution = plan
    png = plot_policy(solution, tmp_path / "p.png", heading=3, layer=1)
    assert png.read_bytes()[:8] == PNG_MAGIC
    assert read_rgb(png).std() > 0.05


def test_bad_arguments_are_rejected(plan, tmp_path):
    u, v, solution = plan
    with pytest.raises(LrauvError, match="heading"):
        plot_policy(solution, tmp_path / "p.png", heading=8)
    with pytest.raises(LrauvError, match="layer"):
        plot_policy(solution, tmp_path / "p.png", layer=2)
    with pytest.raises(LrauvError, match="shape"):
        plot_flow_fields(u[:1], v[:1], solution.model, tmp_path / "f.png")
    land = np.argwhere(~solution.model.water)[0]
    with pytest.raises(LrauvError, match="land"):
        plot_nominal_path(solution, (*land, 0), tmp_path / "n.png")
    assert not list(tmp_path.iterdir())


def test_importing_the_module_does_not_load_matplotlib():
    code = "import sys, planner.shore.plots; sys.exit('matplotlib' in sys.modules or 'numba' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr

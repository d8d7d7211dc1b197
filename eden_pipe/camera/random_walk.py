"""The rig's random walk: straight runs, gradual and abrupt turns, self-rotation.

The planner is independent of any physics engine: it asks ``is_free(x, y)``
whether the ring (with its clearance) fits at a position. When the next step
is blocked it turns abruptly toward a random free direction; when no direction
is free it restarts from a new random start.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class PathParams:
    steps: int
    step_m: float
    run_steps: tuple[int, int]
    turn_deg: tuple[float, float]
    abrupt_turn_probability: float
    gradual_turn_steps: tuple[int, int]
    spin_deg_per_step: tuple[float, float]
    max_attempts: int


class NoFreePath(RuntimeError):
    pass


def plan_path(
    params: PathParams,
    is_free: Callable[[float, float], bool],
    bounds: tuple[float, float, float, float],
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Returns (xy (n, 2), heading (n,), direction of travel (n,)) for n = params.steps."""
    x0, y0, x1, y1 = bounds
    for _attempt in range(params.max_attempts):
        start = None
        for _ in range(500):
            p = rng.uniform([x0, y0], [x1, y1])
            if is_free(*p):
                start = p
                break
        if start is None:
            continue
        path = _walk(params, is_free, bounds, rng, start)
        if path is not None:
            return path
    raise NoFreePath(
        f"no collision-free path of {params.steps} steps found in {params.max_attempts} attempts; "
        "lower the garden's instance counts or camera.trajectory.clearance_m"
    )


def _walk(params: PathParams, is_free, bounds, rng: np.random.Generator, start: np.ndarray):
    x0, y0, x1, y1 = bounds

    def free(p) -> bool:
        return x0 <= p[0] <= x1 and y0 <= p[1] <= y1 and is_free(p[0], p[1])

    pos = np.asarray(start, dtype=np.float64)
    theta = float(rng.uniform(0, 2 * np.pi))
    heading = float(rng.uniform(0, 2 * np.pi))
    run_left = int(rng.integers(params.run_steps[0], params.run_steps[1] + 1))
    spin = np.deg2rad(rng.uniform(*params.spin_deg_per_step))
    turn_left, turn_rate = 0, 0.0
    xy, headings, travel = [pos.copy()], [heading], [theta]
    while len(xy) < params.steps:
        if run_left <= 0 and turn_left <= 0:
            magnitude = np.deg2rad(rng.uniform(*params.turn_deg)) * (1 if rng.random() < 0.5 else -1)
            if rng.random() < params.abrupt_turn_probability:
                theta += magnitude
            else:
                turn_left = int(rng.integers(params.gradual_turn_steps[0], params.gradual_turn_steps[1] + 1))
                turn_rate = magnitude / turn_left
            run_left = int(rng.integers(params.run_steps[0], params.run_steps[1] + 1))
            spin = np.deg2rad(rng.uniform(*params.spin_deg_per_step))
        if turn_left > 0:
            theta += turn_rate
            turn_left -= 1
        else:
            run_left -= 1
        nxt = pos + params.step_m * np.array([np.cos(theta), np.sin(theta)])
        if not free(nxt):
            # Blocked: an abrupt turn to a random free direction (nearest turns first).
            deltas = rng.uniform(-np.pi, np.pi, 32)
            deltas = deltas[np.argsort(np.abs(deltas))]
            for d in deltas:
                cand = pos + params.step_m * np.array([np.cos(theta + d), np.sin(theta + d)])
                if free(cand):
                    theta, nxt = theta + d, cand
                    turn_left = 0
                    break
            else:
                return None
        pos = nxt
        heading += spin
        xy.append(pos.copy())
        headings.append(heading)
        travel.append(theta)
    return np.array(xy), np.array(headings), np.array(travel)

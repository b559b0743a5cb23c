"""Paper 004's kick experiment (Section V, Table I, Fig. 6) in closed loop.

Two robots 2.5 m apart: A at the origin facing +x with the ball just in front,
teammate B at (0, 2.5) facing A. A kicks the ball to its left, towards B, out of
its camera's view. A's head follows its world model: it points the camera at the
best ball estimate (the highest confidence, paper 004's H) and scans (sweeps its
head) when there is none or it is invalid. We measure the time from the kick
until the ball is in A's camera view again, for three world models:

* ``none``: A's own camera only;
* ``teammate``: plus B's ball observations relayed to A (every ``comm_period``
  s, ``comm_delay`` s late, noisier, with the lower confidence of the
  ``teammate`` detector): paper 004's teammate hypotheses;
* ``kick``: plus A's own kick reported as an action (``WorldModel.act``): paper
  004's kick hypotheses.

A's camera scans carry the sensor pose, so a ball estimate in view that the
camera does not report loses existence and confidence quickly (negative
information). Each trial draws the kick's true speed, direction and the ball's
deceleration, how long the kick hides the ball, the scan's first direction and the
teammate's message phase and delay; the three models see the same draws (paired
trials).
"""

from __future__ import annotations

import contextlib
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from semwm.detection import OutOfOrderError
from semwm.knowledge.model import Knowledge
from semwm.world import WorldModel

Model = Literal["none", "teammate", "kick"]
MODELS: tuple[Model, ...] = ("none", "teammate", "kick")
PAPER_TABLE_I = {
    "none": (6.13, 2.35),
    "teammate": (3.99, 1.73),
    "kick": (1.63, 0.38),
}
"""Paper 004 Table I: mean and std of the time to see the ball after a side kick (s)."""


@dataclass(frozen=True)
class KickSetup:
    """The experiment's constants (SI units; angles in degrees where named so)."""

    frame: float = 0.1  # s between camera frames
    kick_time: float = 1.0  # s: the ball is seen at rest before it
    horizon: float = 15.0  # s after the kick: a trial that never sees the ball ends here
    ball_start: tuple[float, float] = (0.5, 0.0)
    teammate: tuple[float, float] = (0.0, 2.5)
    camera_fov_deg: float = 60.0
    camera_range: float = 4.0
    camera_noise: float = 0.03  # m
    camera_pd: float = 0.9
    blind: tuple[float, float] = (0.5, 1.0)  # s after the kick A cannot see the ball
    pan_limit_deg: float = 110.0
    track_speed_deg: float = 180.0  # head speed when following an estimate (deg/s)
    scan_speed_deg: float = 35.0  # head speed when scanning (deg/s)
    kick_speed: float = 1.2  # m/s: nominal (what A reports)
    kick_speed_sd: float = 0.15
    kick_direction_sd_deg: float = 5.0
    alpha_range: tuple[float, float] = (0.3, 0.5)  # true deceleration (m/s^2)
    comm_period: float = 1.0  # s between teammate messages
    comm_delay: tuple[float, float] = (0.3, 0.8)  # s
    teammate_noise: float = 0.15  # m (its localisation error)


@dataclass
class Trial:
    """One trial's outcome: the time to see the ball (s; ``None`` if never within the
    horizon) and the trace of A's best ball estimate."""

    model: Model
    time_to_see: float | None
    times: list[float] = field(default_factory=list)
    confidence: list[float] = field(default_factory=list)
    states: list[str] = field(default_factory=list)
    scanning: list[bool] = field(default_factory=list)


@dataclass(frozen=True)
class Draw:
    speed: float
    direction: float  # rad
    alpha: float
    scan_first: int  # +1 left, -1 right
    comm_phase: float
    delays: tuple[float, ...]
    blind: float  # s: the kick's motion and the shoulder hide the ball this long


def draw(rng: np.random.Generator, setup: KickSetup) -> Draw:
    messages = int((setup.kick_time + setup.horizon) / setup.comm_period) + 2
    return Draw(
        speed=float(rng.normal(setup.kick_speed, setup.kick_speed_sd)),
        direction=math.pi / 2 + math.radians(float(rng.normal(0.0, setup.kick_direction_sd_deg))),
        alpha=float(rng.uniform(*setup.alpha_range)),
        scan_first=int(rng.choice([-1, 1])),
        comm_phase=float(rng.uniform(0.0, setup.comm_period)),
        delays=tuple(float(d) for d in rng.uniform(*setup.comm_delay, size=messages)),
        blind=float(rng.uniform(*setup.blind)),
    )


def ball_at(t: float, setup: KickSetup, d: Draw) -> np.ndarray:
    """The true ball position: at rest, then rolling out at constant deceleration."""
    start = np.asarray(setup.ball_start)
    if t <= setup.kick_time:
        return start
    tau = min(t - setup.kick_time, d.speed / d.alpha)
    travelled = d.speed * tau - d.alpha * tau**2 / 2.0
    return start + travelled * np.array([math.cos(d.direction), math.sin(d.direction)])


def in_view(point: np.ndarray, origin: np.ndarray, heading: float, setup: KickSetup) -> bool:
    offset = point - origin
    if float(np.linalg.norm(offset)) > setup.camera_range:
        return False
    bearing = math.atan2(offset[1], offset[0]) - heading
    bearing = (bearing + math.pi) % (2.0 * math.pi) - math.pi
    return abs(bearing) <= math.radians(setup.camera_fov_deg) / 2.0


def run_trial(
    knowledge: Knowledge, model: Model, d: Draw, rng: np.random.Generator, setup: KickSetup
) -> Trial:
    """One trial of one world model. ``rng`` draws only the sensors' noise and misses."""
    wm = WorldModel(knowledge, reorder_window=1.0)
    trial = Trial(model, None)
    origin = np.zeros(2)
    teammate = np.asarray(setup.teammate)
    teammate_heading = -math.pi / 2
    pan = 0.0
    scanning, direction = False, d.scan_first
    limit = math.radians(setup.pan_limit_deg)
    inbox: list[tuple[float, float, np.ndarray]] = []  # (arrival, measured at, position)
    sent = 0
    steps = round((setup.kick_time + setup.horizon) / setup.frame)
    for step in range(steps + 1):
        t = round(step * setup.frame, 9)
        ball = ball_at(t, setup, d)
        if model == "kick" and abs(t - setup.kick_time) < 1e-9:
            wm.act(
                {
                    "time": t,
                    "type": "kick",
                    "source": "A",
                    "near": list(setup.ball_start),
                    "direction": [0.0, 1.0],
                    "speed": setup.kick_speed,
                }
            )
        # the teammate's relayed observations (B sees the ball in its own view)
        while _due(sent, d, setup) <= t:
            measured = _due(sent, d, setup)
            true = ball_at(measured, setup, d)
            if in_view(true, teammate, teammate_heading, setup):
                seen = true + rng.normal(0.0, setup.teammate_noise, 2)
                inbox.append((measured + d.delays[sent], measured, seen))
            sent += 1
        if model == "teammate":
            for message in [m for m in inbox if m[0] <= t]:
                inbox.remove(message)
                detection = {
                    "time": message[1],
                    "class": "Ball",
                    "position": message[2].tolist(),
                    "source": "B",
                    "detector": "teammate",
                }
                with contextlib.suppress(OutOfOrderError):  # older than the window: lost
                    wm.ingest(detection)
        blind = setup.kick_time <= t < setup.kick_time + d.blind
        visible = not blind and in_view(ball, origin, pan, setup)
        if t > setup.kick_time and visible and trial.time_to_see is None:
            trial.time_to_see = round(t - setup.kick_time, 9)
        # the camera looks every frame (its pose in every scan); during the kick it cannot
        # see the ball
        batch = []
        if visible and rng.random() < setup.camera_pd:
            seen = ball + rng.normal(0.0, setup.camera_noise, 2)
            batch.append({"time": t, "class": "Ball", "position": seen.tolist(), "source": "A"})
        sensor = {"pose": [0.0, 0.0, pan], "time": t, "source": "A", "detector": "camera"}
        wm.ingest(batch, sensor=sensor)
        best = _best_ball(wm, t)
        trial.times.append(t)
        trial.confidence.append(best[0] if best else 0.0)
        trial.states.append(best[1] if best else "none")
        trial.scanning.append(scanning)
        if trial.time_to_see is not None and t >= setup.kick_time + trial.time_to_see + 2.0:
            break
        if blind:
            continue
        if best is None or best[1] == "invalid":
            if not scanning:
                scanning, direction = True, d.scan_first
            pan += direction * math.radians(setup.scan_speed_deg) * setup.frame
            if abs(pan) >= limit:
                pan, direction = math.copysign(limit, pan), -direction
        else:
            scanning = False
            target = math.atan2(best[2][1], best[2][0])
            step_max = math.radians(setup.track_speed_deg) * setup.frame
            pan += max(-step_max, min(step_max, target - pan))
            pan = max(-limit, min(limit, pan))
    return trial


def _due(sent: int, d: Draw, setup: KickSetup) -> float:
    """When the teammate takes its ``sent``-th observation to send (s)."""
    return d.comm_phase + sent * setup.comm_period


def _best_ball(wm: WorldModel, t: float) -> tuple[float, str, tuple[float, ...]] | None:
    """A's ball estimate: the ball with the highest confidence (then existence)."""
    balls = [o for o in wm.world(t, cls="Ball").objects if o.confidence is not None]
    if not balls:
        return None
    best = max(balls, key=lambda o: (o.confidence.value if o.confidence else 0.0, o.existence))
    assert best.confidence is not None
    return best.confidence.value, best.confidence.state, best.position


@dataclass
class KickResult:
    trials: dict[str, list[Trial]]
    seed: int
    setup: KickSetup
    draws: list[Draw]

    def summary(self) -> dict[str, Any]:
        """``time_to_see`` per model: mean, std, trials, and how many never saw it (those
        count as the horizon in mean and std)."""
        result: dict[str, Any] = {}
        for model, trials in self.trials.items():
            values = [
                t.time_to_see if t.time_to_see is not None else self.setup.horizon for t in trials
            ]
            result[model] = {
                "mean": float(np.mean(values)),
                "std": float(np.std(values, ddof=1)) if len(values) > 1 else 0.0,
                "trials": len(values),
                "never_seen": sum(t.time_to_see is None for t in trials),
                "values": values,
            }
        return result


def run_kick(knowledge: Knowledge, seed: int = 0, trials: int = 20) -> KickResult:
    """Every trial of every model; trial ``i`` of each model shares one draw."""
    setup = KickSetup()
    rng = np.random.default_rng(seed)
    draws = [draw(rng, setup) for _ in range(trials)]
    noise_seeds = rng.integers(0, 2**32, size=trials)
    result: dict[str, list[Trial]] = {m: [] for m in MODELS}
    for i, d in enumerate(draws):
        for model in MODELS:
            noise = np.random.default_rng(int(noise_seeds[i]))
            result[model].append(run_trial(knowledge, model, d, noise, setup))
    return KickResult(result, seed, setup, draws)


def write_kick(result: KickResult, out_dir: str | Path, knowledge_file: str) -> Path:
    """``metrics.json`` (``time_to_see`` per model, paper 004's Table I beside it),
    ``trials.jsonl`` (every trial's trace) and ``plot.png`` (a Fig. 6-like confidence
    trace and the times to see)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = result.summary()
    document = {
        "scenario": "kick",
        "seed": result.seed,
        "knowledge": knowledge_file,
        "time_to_see": summary,
        "paper_table_i": {m: {"mean": a, "std": b} for m, (a, b) in PAPER_TABLE_I.items()},
        "order_as_paper": summary["kick"]["mean"]
        < summary["teammate"]["mean"]
        < summary["none"]["mean"],
        "setup": asdict(result.setup),
    }
    (out / "metrics.json").write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    with (out / "trials.jsonl").open("w", encoding="utf-8") as f:
        for trials in result.trials.values():
            for i, trial in enumerate(trials):
                f.write(json.dumps({"trial": i, **asdict(trial)}) + "\n")
    plot_kick(result, out / "plot.png")
    return out


def plot_kick(result: KickResult, path: Path) -> None:
    """Left: A's ball confidence over one trial per model (paper 004 Fig. 6) with the
    valid / suspicious / invalid bands; right: time to see the ball, ours and Table I."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    setup = result.setup
    colours = {"none": "tab:red", "teammate": "tab:blue", "kick": "tab:green"}
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5), width_ratios=(2, 1))
    l_s, l_i = 0.6, 0.3  # knowledge/robocup_kick.yaml's Ball thresholds
    left.axhspan(l_s, 1.05, color="tab:green", alpha=0.08, label="valid")
    left.axhspan(l_i, l_s, color="tab:orange", alpha=0.10, label="suspicious")
    left.axhspan(0.0, l_i, color="tab:red", alpha=0.08, label="invalid")
    index = _typical(result)
    for model, trials in result.trials.items():
        trial = trials[index]
        times = np.asarray(trial.times) - setup.kick_time
        left.plot(times, trial.confidence, color=colours[model], label=f"{model}")
        if trial.time_to_see is not None:
            left.axvline(trial.time_to_see, color=colours[model], ls=":", lw=1)
    left.axvline(0.0, color="k", lw=1)
    left.axvspan(0.0, result.draws[index].blind, color="grey", alpha=0.15)
    left.text(0.02, 1.0, "kick", fontsize=8)
    left.set(
        xlabel="time after the kick (s); dotted: ball in view again",
        ylabel="confidence of A's best ball estimate",
        ylim=(0.0, 1.05),
        xlim=(
            -setup.kick_time,
            max(t.times[-1] for ts in result.trials.values() for t in [ts[index]])
            - setup.kick_time,
        ),
        title=f"A's ball confidence, trial {index} (grey: ball hidden by the kick)",
    )
    left.legend(fontsize=8, loc="upper right")
    summary = result.summary()
    x = np.arange(len(MODELS))
    means = [summary[m]["mean"] for m in MODELS]
    stds = [summary[m]["std"] for m in MODELS]
    right.bar(x - 0.2, means, 0.4, yerr=stds, color=[colours[m] for m in MODELS], label="semwm")
    right.bar(
        x + 0.2,
        [PAPER_TABLE_I[m][0] for m in MODELS],
        0.4,
        yerr=[PAPER_TABLE_I[m][1] for m in MODELS],
        color="lightgrey",
        label="paper 004 Table I",
    )
    right.set_xticks(x, MODELS)
    right.set(
        ylabel="time to see the ball (s)",
        title=f"{summary['none']['trials']} trials, mean ± std",
    )
    right.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _typical(result: KickResult) -> int:
    """The trial whose ``none`` time is closest to its mean (a representative trace)."""
    values = result.summary()["none"]["values"]
    mean = float(np.mean(values))
    return int(np.argmin([abs(v - mean) for v in values]))

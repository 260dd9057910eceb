"""The vision ego's costs: rendering, PilotNet, and vision rollouts against lidar ones.

Three tables, each measured side by side in one process (the machine this
was written on is shared and loaded: compare ratios within a run, not figures
across runs):

1. ``render``: frames/s of :class:`avrisk.render.RayCastCamera` at 66 x 200
   with the ``highway_vision`` scene (ego + 5 vehicles), by batch size, eager
   and compiled (``torch.compile(fullgraph=True)``, compilation outside the
   timing);
2. ``pilotnet``: frames/s of PilotNet inference (no gradients) by batch
   size, as :meth:`PilotNet.steer` runs it (eager, fixed inner batches)
   and as a plain forward pass on the whole batch: eager, channels-last
   memory format, and ``torch.compile``;
3. ``rollouts``: full 10 s rollouts/s of ``highway_vision`` (the vision ego:
   camera + PilotNet + lidar throttle) and ``highway_default`` (the lidar
   ego) on the same scenes, one batch size, eager and/or compiled
   (``--rollout-modes``; ``AVRISK_COMPILE=1``: the whole step as one graph,
   compilation in the first call, reported apart), with the largest
   difference in ``f`` between compiled and eager.

``--sections`` picks the tables (default all three).

Usage::

    .venv/bin/python benchmarks/vision_throughput.py                # CPU, 1 thread
    .venv/bin/python benchmarks/vision_throughput.py --quick        # smoke test
    .venv/bin/python benchmarks/vision_throughput.py --device cuda \
        --render-batches 256,4096,16384 --net-batches 256,4096 --rollout-batch 1024

Writes JSON to ``--out`` (default ``benchmarks/results/vision_throughput.json``)
and prints Markdown tables.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from avrisk.agents.vision import PilotNet, inner_batch, load_pilotnet
from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.parts import (
    base_distribution,
    camera_from_spec,
    initial_state,
    param_layout,
)
from avrisk.scenario import ScenarioParams, load_spec
from avrisk.sim.config import COMPILE_ENV


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def _rate(fn: Any, items: int, device: str, repeats: int, min_seconds: float) -> float:
    """Items per second: the median over ``repeats`` timings of ``fn``."""
    fn()  # warm-up
    _sync(device)
    rates = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while True:
            fn()
            calls += 1
            _sync(device)
            elapsed = time.perf_counter() - start
            if elapsed >= min_seconds:
                break
        rates.append(calls * items / elapsed)
    return statistics.median(rates)


def _scene_states(batch: int, device: str) -> Any:
    """Initial states of ``batch`` draws from ``highway_vision``'s P0."""
    spec = load_spec("highway_vision")
    x = base_distribution(spec).sample(batch, np.random.default_rng(0))
    params = ScenarioParams.from_flat(x, param_layout(spec))
    return spec, initial_state(params, spec, device=device)


def bench_render(
    batches: list[int], modes: list[str], device: str, args: argparse.Namespace
) -> list[dict[str, Any]]:
    rows = []
    for batch in batches:
        spec, state = _scene_states(batch, device)
        camera = camera_from_spec(spec, device=device)
        for mode in modes:
            fn = camera if mode == "eager" else torch.compile(camera, fullgraph=True)
            if mode != "eager":
                fn(state)  # compile outside the timing
            rate = _rate(
                lambda f=fn, s=state: f(s), batch, device, args.repeats, args.seconds
            )
            rows.append({"batch": batch, "mode": mode, "frames_per_s": rate})
            print(f"render B={batch} {mode}: {rate:,.0f} frames/s", flush=True)
    return rows


def bench_pilotnet(
    batches: list[int], modes: list[str], device: str, args: argparse.Namespace
) -> list[dict[str, Any]]:
    rows = []
    net = _net(args).to(device).eval()
    for batch in batches:
        images = torch.rand(batch, 3, 66, 200, device=device)
        inner = f"steer (inner batches of {inner_batch(images.device)})"
        variants: dict[str, Any] = {inner: net.steer}
        if "eager" in modes:
            variants["forward"] = net
        if "channels_last" in modes:
            cl = PilotNet().to(device).eval()
            cl.load_state_dict(net.state_dict())
            cl = cl.to(memory_format=torch.channels_last)
            cl_images = images.contiguous(memory_format=torch.channels_last)
            variants["forward, channels-last"] = lambda _x, m=cl, i=cl_images: m(i)
        if "compiled" in modes:
            compiled = torch.compile(net)
            variants["forward, compiled"] = compiled
        for name, fn in variants.items():
            with torch.no_grad():
                fn(images)  # compile / warm up outside the timing
                rate = _rate(
                    lambda f=fn, i=images: f(i),
                    batch,
                    device,
                    args.repeats,
                    args.seconds,
                )
            rows.append({"batch": batch, "variant": name, "frames_per_s": rate})
            print(f"pilotnet B={batch} {name}: {rate:,.0f} frames/s", flush=True)
    return rows


def _net(args: argparse.Namespace) -> PilotNet:
    try:
        return load_pilotnet(args.weights)
    except FileNotFoundError:
        torch.manual_seed(0)
        return PilotNet()  # same cost: the weights' values do not matter here


def bench_rollouts(
    batch: int, modes: list[str], device: str, args: argparse.Namespace
) -> list[dict]:
    rows = []
    x = base_distribution(load_spec("highway_vision")).sample(
        batch, np.random.default_rng(1)
    )
    seeds = np.arange(batch)
    for mode in modes:
        for scenario in ("highway_default", "highway_vision"):
            os.environ[COMPILE_ENV] = "1" if mode == "compiled" else "0"
            sim = ScenarioSimulator(load_spec(scenario), device=device)
            start = time.perf_counter()
            first = sim.rollout(x, seeds)  # warm-up; compiles when compiled
            warm_up = time.perf_counter() - start
            times = []
            for _ in range(args.repeats):
                _sync(device)
                start = time.perf_counter()
                sim.rollout(x, seeds)
                _sync(device)
                times.append(time.perf_counter() - start)
            rate = batch / statistics.median(times)
            row = {
                "scenario": scenario,
                "mode": mode,
                "batch": batch,
                "rollouts_per_s": rate,
                "first_call_s": warm_up,
                "f": first.f.tolist(),
            }
            rows.append(row)
            print(
                f"rollouts {scenario} {mode} B={batch}: {rate:,.2f} rollouts/s "
                f"(first call {warm_up:.0f} s)",
                flush=True,
            )
    os.environ.pop(COMPILE_ENV, None)
    for scenario in ("highway_default", "highway_vision"):
        f = {r["mode"]: np.array(r["f"]) for r in rows if r["scenario"] == scenario}
        if len(f) == 2:
            gap = float(np.nanmax(np.abs(f["compiled"] - f["eager"])))
            print(f"{scenario}: max |f compiled - f eager| = {gap:.3g} s")
    return rows


def _ints(text: str) -> list[int]:
    return [int(v) for v in text.split(",") if v]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--render-batches", type=_ints, default=[1, 16, 64, 256])
    parser.add_argument("--render-modes", default="eager,compiled")
    parser.add_argument("--net-batches", type=_ints, default=[1, 32, 256])
    parser.add_argument("--net-modes", default="eager,channels_last,compiled")
    parser.add_argument("--rollout-batch", type=int, default=64)
    parser.add_argument("--rollout-modes", default="eager")
    parser.add_argument("--sections", default="render,pilotnet,rollouts")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--weights", default=None, help="PilotNet .npz (shipped)")
    parser.add_argument("--quick", action="store_true", help="tiny smoke run")
    parser.add_argument(
        "--out", type=Path, default=Path("benchmarks/results/vision_throughput.json")
    )
    args = parser.parse_args()
    if args.quick:
        args.render_batches, args.net_batches, args.rollout_batch = [2], [2], 2
        args.render_modes, args.net_modes = "eager", "eager"
        args.repeats, args.seconds = 1, 0.1
    torch.set_num_threads(args.threads)
    device = args.device
    load = os.getloadavg()
    result = {
        "command": "benchmarks/vision_throughput.py " + " ".join(sys.argv[1:]),
        "device": device,
        "torch_threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "load_average_before": load,
        "uptime_before": _uptime(),
    }
    sections = args.sections.split(",")
    if "render" in sections:
        result["render"] = bench_render(
            args.render_batches, args.render_modes.split(","), device, args
        )
    if "pilotnet" in sections:
        result["pilotnet"] = bench_pilotnet(
            args.net_batches, args.net_modes.split(","), device, args
        )
    if "rollouts" in sections:
        result["rollouts"] = bench_rollouts(
            args.rollout_batch, args.rollout_modes.split(","), device, args
        )
    result["uptime_after"] = _uptime()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}; load before {load}, after {result['uptime_after']}")


def _uptime() -> str:
    try:
        return subprocess.run(
            ["uptime"], capture_output=True, text=True, check=False
        ).stdout.strip()
    except OSError:
        return ""


if __name__ == "__main__":
    main()

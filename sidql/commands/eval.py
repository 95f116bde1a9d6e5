"""``sidql eval``: every keyframe method on every 60-frame clip of a folder of CMU trials."""

from __future__ import annotations

import json
from pathlib import Path

from sidql.commands.usage import (
    UsageError,
    add_data,
    add_flat_floor,
    add_keyframes,
    add_methods,
    add_quiet,
    add_ray,
    add_reconstruction,
    add_samples,
    add_skeleton,
    add_test_subjects,
    add_workers,
    check_keyframes,
    cmu_rate,
    data_folder,
    positive,
)
from sidql.evaluation.cases import load_cases
from sidql.evaluation.evaluate import evaluate
from sidql.evaluation.rate import rate_distortion, write_plot
from sidql.evaluation.significance import comparisons_markdown, versus_original_markdown
from sidql.evaluation.tables import (
    floors_markdown,
    physics_markdown,
    simulate_markdown,
    table3_markdown,
)
from sidql.keyframes import reconstructions
from sidql.keyframes.methods import get
from sim.batch import ray_session
from sim.files import write_atomic
from sim.simulate.validate import chosen_controller

DESCRIPTION = (
    "Cut every trial under --data into clips of --length frames at --fps (60 frames at 30 fps by "
    "default), choose W keyframes per clip with each method, rebuild the clip with the method's reconstruction (spherical Hermite; pitch: "
    "slerp; cartesian: points in xyz) and report the paper's Q (eq. 18) beside its Table 3, plus "
    "geodesic, MPJPE, velocity and Li et al. errors and decision times. Optionally write the "
    "rate/distortion plot."
)


def register(p) -> None:
    add_data(p)
    add_keyframes(p, "values of W (keyframes per clip)", default=[5, 10, 15], many=True)
    add_methods(
        p, ["random", "uniform", "greedy", "optimal", "pitch"],
        "methods to run (registered in sidql.keyframes.methods; e.g. dqn, the shipped policy, "
        "or cartesian)",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="seed of the random method")
    p.add_argument("--fps", type=cmu_rate, default=30.0, help="clip frame rate (divides 120)")
    p.add_argument("--length", type=positive(int), default=60, metavar="N", help="frames per clip")
    add_skeleton(p)
    p.add_argument(
        "--out", default="results.json", metavar="F.json",
        help="JSON of results and per-clip rows",
    )  # fmt: skip
    p.add_argument(
        "--rate-plot",
        default=None,
        metavar="PNG",
        help="also sweep W and write the rate/distortion plot here (and its data beside it)",
    )
    add_test_subjects(
        p, "evaluate only these subjects, e.g. 01 07 18 61 (a policy's held-out ones: "
        "train --test-subjects)", old_option="--subjects",
    )  # fmt: skip
    p.add_argument(
        "--physics",
        action="store_true",
        help="also fit the subject's humanoid to every reconstruction and the original and add "
        "ground-contact, self-penetration, joint-limit and inverse-dynamics figures "
        "(sim.physics) to every row, plus rows for method 'original' and its 'noise floor' (the "
        "original re-captured with 1.5 mm marker noise), each trial's floor fit (trials whose "
        "floor does not fit are listed) and paired bootstrap comparisons of the methods",
    )
    p.add_argument(
        "--simulate",
        action="store_true",
        help="with --physics: also track the original's and every reconstruction's fit in "
        "MuJoCo's forward simulation with the human-strength controller and no assistance; "
        "adds tracking errors, falls and torque per method (sim.simulate.validate)",
    )
    add_samples(p, "with --simulate: track", old_option="--simulate-samples")
    add_flat_floor(p)
    p.add_argument(
        "--threads", type=positive(int), default=1, metavar="N",
        help="with --simulate: the sampler's rollouts on N threads in each worker (the figures "
        "do not depend on it)",
    )  # fmt: skip
    p.add_argument(
        "--max-clips", type=positive(int), default=None, metavar="N",
        help="evaluate only the first N clips (e.g. to bound a --simulate run)",
    )  # fmt: skip
    add_reconstruction(p)
    add_quiet(p)
    add_workers(p, "loading trials and evaluating clips (methods, physics, simulation)")
    add_ray(p, "the trials' loading and the clips' evaluation")
    p.set_defaults(func=run)


def run(args) -> int:
    with ray_session(args.ray, args.workers):  # Ray started or joined once for both batches
        return _run(args)


def _run(args) -> int:
    for name in args.methods:  # unknown names fail before the (slow) ingest
        get(name)
    if args.reconstruction is not None:
        reconstructions.get(args.reconstruction)
    counts = check_keyframes(args, args.length)
    _check_simulation_options(args)
    args.data = data_folder(args)
    cases, skipped = load_cases(
        args.data,
        fps=args.fps,
        length=args.length,
        skeleton=args.skeleton,
        progress=not args.quiet,
        subjects=args.test_subjects,
        workers=args.workers,
        ray=args.ray,
    )
    if args.simulate and not args.physics:
        raise UsageError("--simulate needs --physics (it tracks the physics' IK fit)")
    if args.max_clips is not None:
        cases = cases[: args.max_clips]
    if not cases:
        raise UsageError(f"{args.data}: no {args.length}-frame clips (skipped {len(skipped)} bad)")
    out = evaluate(
        cases, args.methods, counts, seed=args.seed, progress=not args.quiet,
        physics=args.physics, simulate=args.simulate,
        simulate_samples=args.samples or 0, simulate_threads=args.threads,
        simulate_terrain=not args.flat_floor,
        workers=args.workers, ray=args.ray, reconstruction=args.reconstruction,
    )  # fmt: skip
    out["skipped"] = skipped
    out["protocol"] = {
        "data": str(args.data),
        "fps": args.fps,
        "length": args.length,
        "skeleton": args.skeleton,
        "seed": args.seed,
        "clips": len(cases),
        "physics": bool(args.physics),
        "simulate": bool(args.simulate),
        # the controller that ran (the default: the sampler at its default count)
        **_simulation_protocol(args.samples or 0),
        # the scene the bodies stood in (sim.simulate.terrain: inferred from each clip's motion)
        "simulate_scene": "flat floor" if args.flat_floor else "inferred",
        "max_clips": args.max_clips,
        "reconstruction": args.reconstruction,
    }
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, lambda f: f.write(json.dumps(out, indent=1).encode()))
    print(f"{len(cases)} clips of {args.length} frames from {args.data}; skipped {len(skipped)}")
    print(table3_markdown(out["results"]))
    if args.physics:
        print(floors_markdown(out["floors"]))
        print("physics, means over clips:")
        print(physics_markdown(out["results"]))
        print("physics, medians over clips:")
        print(physics_markdown(out["results"], "median"))
    if out.get("comparisons"):
        print("paired comparisons over clips (bootstrap 95 % CI):")
        print(comparisons_markdown(out["comparisons"]))
    if args.simulate:
        print("forward simulation (human-strength body, no assistance), means over clips:")
        print(simulate_markdown(out["results"]))
        print("each method against the original on the same clips (paired bootstrap):")
        print(versus_original_markdown(out["versus_original"]))
    print(f"wrote {path}")
    if args.rate_plot:
        rd = rate_distortion(cases, seed=args.seed, progress=not args.quiet)
        png = Path(args.rate_plot)
        png.parent.mkdir(parents=True, exist_ok=True)
        write_plot(rd, png)
        data = png.with_suffix(".json")
        write_atomic(data, lambda f: f.write(json.dumps(rd, indent=1).encode()))
        print(f"wrote {png} and {data}")
    return 0


def _check_simulation_options(args) -> None:
    """``--samples``, ``--threads`` and ``--flat-floor`` are ``--simulate``'s."""
    for given, flag in ((args.samples, "--samples"), (args.threads > 1, "--threads"),
                        (args.flat_floor, "--flat-floor")):  # fmt: skip
        if given and not args.simulate:
            raise UsageError(f"{flag} needs --simulate")


def _simulation_protocol(samples: int) -> dict:
    controller, count = chosen_controller(samples)
    return {"simulate_controller": controller, "simulate_samples": count}

"""``sidql synth --data DIR --n N --out DIR``: simulated, velocity-rich clips in the dataset format."""

from __future__ import annotations

from argparse import BooleanOptionalAction

from sidql.commands.usage import (
    UsageError,
    add_data,
    add_flat_floor,
    add_quiet,
    add_ray,
    add_samples,
    add_workers,
    cmu_rate,
    data_folder,
    positive,
)
from sim.simulate.dataset import synthesize
from sim.simulate.export import DATASET_ID, DEFAULT_ID, export_minari
from sim.simulate.generate import (
    ALL_KINDS,
    CLIP_SECONDS,
    KINDS,
    SYNTH_CONTACT_REFERENCE,
    SYNTH_CONTROLLERS,
    SYNTH_DEFAULT_CONTROLLER,
    SYNTH_DRIFT,
    SYNTH_FOOT_LOCK,
    SYNTH_GAIN_CHOICE,
    SYNTH_LEAN,
)

DESCRIPTION = (
    "Track real trials under --data with a controller in MuJoCo's forward simulation (by default "
    "eval --simulate's sampler; time warps, body scaling, gain changes, pushes), make the figure "
    "fall and recover, or track procedural "
    "motion; the body has human strength and no help unless --assist asks for it (procedural "
    "clips are tracked with help, recorded), and real trials are tracked in the scene inferred "
    "from them, as eval --simulate does (steps under feet that stand on something; "
    "--flat-floor: the empty floor); write OUT/<kind>/<kind>_NNNNN.npz in the `sidql "
    "dataset` format plus OUT/index.json "
    "recording every clip's parameters, seed, per-frame root assistance and tracking error. "
    "Positions and velocities are the simulator's state. The same --seed gives the same clips bit "
    "for bit. Bad input is skipped and listed."
)


def register(p) -> None:
    add_data(p, "folder of CMU trials to track (kinds other than procedural)", old_option="--from")
    p.add_argument("--n", type=positive(int), required=True, help="number of clips")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    p.add_argument(
        "--kinds",
        nargs="+",
        choices=ALL_KINDS,
        default=list(KINDS),
        metavar="KIND",
        help=f"clip kinds, of {', '.join(ALL_KINDS)} (follow: unperturbed tracking, the baseline; "
        "procedural: sinusoids tracked with up to 1 body weight of recorded root assistance)",
    )
    p.add_argument(
        "--controller", choices=SYNTH_CONTROLLERS, default=None,
        help=f"controller of the real-motion kinds (default: {SYNTH_DEFAULT_CONTROLLER}, eval "
        "--simulate's, with no assistance; plain: the plain tracker, about a twentieth of the "
        "sampler's cost, which falls in nearly every clip)",
    )  # fmt: skip
    p.add_argument(
        "--threads", type=positive(int), default=1, metavar="N",
        help="threads for the sampler's rollouts in each worker (the clips do not depend on it)",
    )  # fmt: skip
    p.add_argument(
        "--assist", type=float, default=0.0, metavar="BW",
        help="let a root assistance of up to BW body weights help the plain tracker on the "
        "real-motion kinds (recorded per tick; default 0: none)",
    )  # fmt: skip
    p.add_argument(
        "--seconds",
        type=positive(float),
        default=CLIP_SECONDS,
        metavar="S",
        help="clip length [s] (default: the protocol's 60 frames at 30 fps)",
    )
    p.add_argument("--fps", type=cmu_rate, default=30.0, help="clip rate (divides 120)")
    add_workers(p, "the simulations")
    add_ray(p, "the simulations")
    p.add_argument(
        "--max-assistance", type=float, default=None, metavar="BW",
        help="keep only clips whose mean root assistance is at most BW body weights, force and "
        "torque (x 1 m) (0.05: the physical clips); others are dropped and more simulated (up "
        "to 20x --n tasks)",
    )  # fmt: skip
    add_samples(p, "track real trials (not procedural clips)")
    for flag, default, what in (
        ("drift", SYNTH_DRIFT, "the sampler's balance feedback with eval --simulate's drift lead"),
        ("contact-reference", SYNTH_CONTACT_REFERENCE,
         "the sampler tracks the contact-consistent reference (else lifted 1 cm)"),
        ("lean", SYNTH_LEAN, "the body stepped lean (the same motion, cheaper steps)"),
        ("foot-lock", SYNTH_FOOT_LOCK, "the contact-consistent reference's stance soles held "
         "still, flat on the floor, by the legs (needs --contact-reference with the sampler)"),
    ):  # fmt: skip
        p.add_argument(f"--{flag}", action=BooleanOptionalAction, default=None,
                       help=f"{what} (default: {'on' if default else 'off'}; recorded)")  # fmt: skip
    add_flat_floor(p, "track the real-motion kinds", "trial")
    p.add_argument(
        "--gain-choice", type=float, default=None, metavar="SHARE",
        help="share of the sampler's candidates per window that roll out on the stiff feedback "
        "gains, the gains chosen with the candidate (0: the body's gains alone; default "
        f"{SYNTH_GAIN_CHOICE:g}); each tick's gains are stored with its action, so episodes "
        "still replay bit for bit (recorded)",
    )  # fmt: skip
    p.add_argument(
        "--resume", action="store_true",
        help="continue the run whose journal (OUT/journal.jsonl) is in --out: clips are stored "
        "as they arrive, so a stopped run keeps them and is not simulated again",
    )  # fmt: skip
    p.add_argument(
        "--export-minari", default=None, metavar="ROOT",
        help="also write the clips as a Minari dataset under ROOT (load it with "
        "MINARI_DATASETS_PATH=ROOT minari.load_dataset(ID); layout in docs/synthetic.md)",
    )  # fmt: skip
    p.add_argument(
        "--minari-id", default=DEFAULT_ID, metavar="ID",
        help="the Minari dataset id, (namespace/)name-v<version>",
    )  # fmt: skip
    add_quiet(p)
    p.set_defaults(func=run)


def run(args) -> int:
    if 120 % args.fps or args.seconds * args.fps < 2:
        raise UsageError("--fps must divide 120 and a clip (--seconds x --fps) hold 2 frames")
    if args.max_assistance is not None and not args.max_assistance >= 0:
        raise UsageError(f"--max-assistance must be >= 0 body weights; got {args.max_assistance}")
    if args.samples and args.controller not in (None, "sampling"):
        raise UsageError(f"--samples is the sampler's; not for --controller {args.controller}")
    if not 0 <= args.assist <= 1 or (args.assist and (args.samples or args.controller != "plain")):
        raise UsageError(
            f"--assist must be 0 .. 1 body weights, with the plain tracker; got {args.assist}"
        )
    if args.gain_choice is not None and not 0 <= args.gain_choice <= 1:
        raise UsageError(f"--gain-choice must be a share 0 .. 1; got {args.gain_choice}")
    if args.gain_choice and args.controller not in (None, "sampling"):
        raise UsageError(f"--gain-choice is the sampler's; not for --controller {args.controller}")
    if not 0 <= args.seed < 2**31:
        raise UsageError(f"--seed must be in 0 .. 2**31 - 1; got {args.seed}")
    if args.export_minari and not DATASET_ID.match(args.minari_id):
        raise UsageError(f"--minari-id {args.minari_id!r}: expected (namespace/)name-v<version>")
    data = data_folder(args, required=any(k != "procedural" for k in args.kinds))
    s = synthesize(
        data, args.out, args.n, seed=args.seed, kinds=tuple(args.kinds),
        seconds=args.seconds, fps=args.fps, samples=args.samples or 0,
        controller=args.controller, assist=args.assist, threads=args.threads,
        workers=args.workers, ray=args.ray,
        progress=not args.quiet, max_assistance=args.max_assistance, resume=args.resume,
        drift=args.drift, contact_reference=args.contact_reference, lean=args.lean,
        gain_choice=args.gain_choice, foot_lock=args.foot_lock,
        terrain=False if args.flat_floor else None,
    )  # fmt: skip
    frames = sum(r["frames"] for r in s.written)
    print(f"simulated {len(s.written)} clips ({frames} frames) in {s.seconds:.1f} s -> "
          f"{args.out}/index.json")  # fmt: skip
    if args.max_assistance is not None:
        counts = ", ".join(f"{k} {v}" for k, v in sorted(s.rejected.items())) or "none"
        print(f"rejected (mean assistance > {args.max_assistance:g} BW): {counts}")
        if len(s.written) < args.n:
            print(f"only {len(s.written)} of {args.n} clips within the budget")
    if args.export_minari and s.written:
        n = export_minari(args.out, args.export_minari, args.minari_id)
        print(f"exported {n} episodes -> {args.export_minari}/{args.minari_id}")
    if s.skipped:
        print(f"skipped {len(s.skipped)} bad input(s)/task(s):")
        for r in s.skipped:
            print(f"  {r['error']}")
    return 1 if s.skipped and not s.written else 0

# PYTHON_ARGCOMPLETE_OK  (argcomplete: this entry point completes; see README, 'Installed as a package')
"""Command line: ``mcl run``, ``mcl eval``, ``mcl tune``, ``mcl simulate``, ``mcl bag info``, ``mcl convert``, ``mcl config``.

Known errors (MclError: a bad config, map or log) print one line on stderr and
exit with status 2; an interrupted run exits with 130 after saving what it
did. Imports are cheap here: the numerical modules load only when a command
runs, so ``mcl --help`` is instant.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import sys
import time
import warnings
from pathlib import Path

from mcl.errors import DataError, MclError, MclWarning

EXIT_ERROR = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: what a shell reports for cat or grep whose reader left


def _project_default_config() -> Path | None:
    from mcl.config import shipped

    p = shipped("configs/default.yaml")
    return p if p.exists() else None


def _add_run(sub) -> None:
    p = sub.add_parser(
        "run",
        help="localize a log on a map; write trajectory.tum, quality.csv, recording.rrd, config.yaml, summary.json",
        description=(
            "Replay a logged dataset (odometry + laser scans) against an occupancy-grid map with Monte Carlo "
            "localization. With no arguments, runs the bundled demo (configs/default.yaml, data/demo). "
            "Every option below overrides the config file; --set reaches any config key."
        ),
        epilog=(
            "examples:\n"
            "  mcl run\n"
            "  mcl run configs/intel_lab.yaml --particles 5000 --seed 1\n"
            "  mcl run --map M.yaml --log L.clf --truth T.tum --out runs/x --global\n"
            "  mcl run configs/mit_csail.yaml --set sensor.model=beam --set filter.particles=5000\n"
            "open the recording with: rerun runs/x/recording.rrd"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("config", nargs="?", help="YAML config (default: configs/default.yaml, the bundled demo)")
    p.add_argument("--config", dest="config_option", metavar="CONFIG",
                   help="the same YAML config, spelled as the other commands take it")
    p.add_argument("--map", help="ROS map_server YAML of the occupancy grid")
    p.add_argument("--log", help="CARMEN log (.clf, plain or gzip; a ROS bag given here is read as --bag); replaces the "
                   "config's log, and its truth "
                   "unless --truth is given")
    p.add_argument("--bag", help="ROS bag instead of a log: .bag (ROS 1), .db3 / .mcap (ROS 2) or a rosbag2 folder; "
                   "its /map stands in for --map (see 'mcl bag info')")
    p.add_argument("--scan-topic", metavar="TOPIC", help="bag: LaserScan/PointCloud2 topic, or 'all' to fuse them (topics.scan)")
    p.add_argument("--odom-topic", metavar="TOPIC", help="bag: nav_msgs/Odometry topic (or a PoseStamped / PoseWithCovarianceStamped "
                   "topic in the odometry frame), 'tf' for odom -> base on /tf, or 'laser' for the scans' own "
                   "motion (scan matching; what a bag without odometry gets) (topics.odom)")
    p.add_argument("--odom-frame", metavar="FRAME", help="bag: odometry frame (frames.odom, default odom)")
    p.add_argument("--base-frame", metavar="FRAME", help="bag: robot frame (frames.base, default base_link)")
    p.add_argument("--write-bag", action="store_true",
                   help="bag: also write estimate.<kind of the input>: /amcl_pose, map -> odom on /tf, /particlecloud")
    p.add_argument("--truth", help="reference trajectory (TUM) to score the run against")
    p.add_argument("--truth-topic", metavar="TOPIC", help="bag: reference poses from this topic (topics.truth)")
    p.add_argument("--out", help="output folder (default: a fresh folder under runs/)")
    p.add_argument("--particles", type=int,
                   help="particles (filter.particles): with KLD sampling (the default) the count drawn at a global "
                        "start and KLD's cap, the set shrinking once the cloud converges (tracking: about 5,000); "
                        "with --set filter.kld=false the fixed count. A global re-seed's updates hold up to twice "
                        "as many (the kept cloud and as many fresh poses)")
    p.add_argument("--seed", type=int, help="random seed: the same seed gives the same trajectory")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--initial-pose", nargs=3, type=float, metavar=("X", "Y", "THETA"), help="start pose for tracking (m, m, rad)")
    g.add_argument("--global", dest="global_", action="store_true", help="global localization: particles uniform over free space")
    p.add_argument("--initial-std", nargs=3, type=float, metavar=("SX", "SY", "STHETA"),
                   help="how far off the start pose may be: the std of the initial cloud around it (m, m, rad; "
                   "filter.initial_std). Default 0.1 0.1 0.1, a pose known to about 0.1 m (a reference's, a "
                   "docking station's); for a pose clicked on a map or guessed by eye, 0.3 0.3 0.2 (from starts 0.7 m "
                   "and 17 degrees off, the largest error passed 0.5 m in 10 of 86 generated runs against 28 with "
                   "0.1; README, 'How good is your start pose?')")
    p.add_argument(
        "--rerun",
        choices=["save", "spawn", "serve", "off"],
        help="save: write recording.rrd (default); spawn: open the viewer (falls back to save without a display); "
        "serve: serve to a web viewer; off: no recording",
    )
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override any config key, e.g. sensor.likelihood_field.sigma_hit=0.1 (repeatable)")
    p.add_argument("--threads", type=int, metavar="N",
                   help="numba threads for the large parallel kernels (default: every core; 1 = serial). The result "
                   "is the same whatever N; on a machine another job keeps busy, 1 avoids waiting for its core")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=cmd_run)


_START_KEYS = ("filter.initial_pose", "filter.global_localization")


def _set_keys(items) -> list[str]:
    """The dotted keys ``--set`` items give, a section given whole included (``filter={initial_pose: [...]}``
    gives filter.initial_pose), in their order; a malformed item as it reads (its error comes from the config)."""
    from mcl.config import parse_override
    from mcl.errors import ConfigError

    keys = []
    for item in items:
        try:
            path, value = parse_override(item)
        except ConfigError:
            keys.append(item.split("=", 1)[0].strip())
            continue
        key = ".".join(path)
        keys.append(key)
        if isinstance(value, dict):
            keys += [f"{key}.{k}" for k in value]
    return keys


def _data_replaced(config_path, set_items, *, log=None, map_=None, truth=None, start_given: bool = False) -> list[str]:
    """The overrides a new log or bag (an option, or ``--set log=`` / ``bag=``) makes: the config's reference
    trajectory belongs to the config's log, so it goes unless given too (scored against another log it is noise: a
    --set log=... kept the demo's truth, and the run was scored 13.9 m off against it). With a new map as well, the
    config's start pose goes too (unless given), as it lies in the config's map: intel_lab's start on the demo's map
    was an unknown cell (every weight zero, lost in 344 of 350 updates). A new log on the config's map keeps it (a
    shortened copy of the log, another recording from the same dock). ``mcl run``'s note says when it goes."""
    set_keys = set(_set_keys(set_items))
    if not (log or set_keys & {"log", "bag"}):
        return []
    out = [] if truth is not None or "truth" in set_keys else ["truth=null"]
    new_map = map_ is not None or "map" in set_keys
    if new_map and not start_given and not set_keys & set(_START_KEYS) and config_path is not None:
        import warnings

        from mcl.config import load_config

        with warnings.catch_warnings():  # the config as given, for its start alone (the run's load says the rest)
            warnings.simplefilter("ignore")
            try:
                own = load_config(config_path, [])
            except MclError:
                own = None  # the run's load gives the error
        # only a config with data of its own has a pose of that data (a file of filter settings alone keeps it)
        if (own is not None and (own.log or own.bag) and own.filter.initial_pose is not None
                and not own.filter.global_localization):
            out.append("filter.initial_pose=null")
    return out


def cmd_run(args) -> int:
    from mcl.config import load_config
    from mcl.runner import check_out_dir, default_out_dir, run, summary_json

    config_path = args.config
    if args.config_option is not None:
        if config_path is not None and config_path != args.config_option:
            raise MclError(f"two configs given: {config_path} and --config {args.config_option}; give one")
        config_path = args.config_option
    overrides = []
    if args.log and not args.bag:
        from mcl.datasets.rosbag import is_bag

        if is_bag(args.log):  # a bag given as the log: read as --bag
            args.bag, args.log = args.log, None
    if config_path is None:
        # No config: the documented defaults of configs/default.yaml, with the user's data instead of the demo's.
        config_path = _project_default_config()
        if args.bag:
            # a bag may hold its own map (/map): --map is optional
            overrides += ["map=null", "log=null"]
        elif args.map or args.log:
            if not (args.map and args.log):
                raise MclError("--map and --log go together when no config file is given")
    start_given = args.initial_pose is not None or args.global_
    replaced = _data_replaced(config_path, args.set, log=args.log or args.bag, map_=args.map, truth=args.truth,
                              start_given=start_given)
    overrides += replaced
    if args.bag and args.log:
        raise MclError("--bag and --log: give one")
    if args.bag:
        overrides.append("log=null")
    elif args.log:
        overrides.append("bag=null")
    if args.truth and args.truth_topic:
        raise MclError("--truth and --truth-topic: give one")
    if args.truth_topic:
        overrides.append("truth=null")  # the topic instead of a config's truth file
    # an option's value that the config rejects names the option (load_config's (option, key=value) pairs)
    for key, value in (("map", args.map), ("log", args.log), ("bag", args.bag), ("truth", args.truth)):
        if value is not None:
            overrides.append((f"--{key} {value}", f"{key}={str(Path(value).resolve())}"))
    for key, value, option in (("topics.scan", args.scan_topic, "--scan-topic"),
                               ("topics.odom", args.odom_topic, "--odom-topic"),
                               ("topics.truth", args.truth_topic, "--truth-topic"),
                               ("frames.odom", args.odom_frame, "--odom-frame"),
                               ("frames.base", args.base_frame, "--base-frame")):
        if value is not None:
            overrides.append((f"{option} {json.dumps(value)}", f"{key}={json.dumps(value)}"))
    if args.particles is not None:
        overrides.append((f"--particles {args.particles}", f"filter.particles={args.particles}"))
    if args.seed is not None:
        overrides.append((f"--seed {args.seed}", f"seed={args.seed}"))
    if args.initial_pose is not None:
        x, y, th = args.initial_pose
        option = f"--initial-pose {x!r} {y!r} {th!r}"
        overrides += [(option, f"filter.initial_pose=[{x!r}, {y!r}, {th!r}]"),
                      (option, "filter.global_localization=false")]
    if args.global_:
        overrides.append(("--global", "filter.global_localization=true"))
    if args.initial_std is not None:
        sx, sy, sth = args.initial_std
        overrides.append((f"--initial-std {sx!r} {sy!r} {sth!r}", f"filter.initial_std=[{sx!r}, {sy!r}, {sth!r}]"))
    if args.rerun is not None:
        overrides.append((f"--rerun {args.rerun}", f"rerun.mode={args.rerun}"))
    cfg = load_config(config_path, overrides + list(args.set))
    options = {o[1].split("=", 1)[0]: o[0] for o in overrides if isinstance(o, tuple)}
    for item in args.set:  # a --set is applied last: it wins over an option that sets the same key, and says so
        # (once the config took it: a malformed --set is its error line alone; a section given whole, its keys)
        for key in dict.fromkeys(_set_keys([item])):
            if key in options:
                print(f"mcl: warning: --set {item} overrides {options[key]}", file=sys.stderr)
    if args.threads is not None:
        set_threads(args.threads)
    out = Path(args.out) if args.out else default_out_dir()
    # before the data loads: a folder mcl may write in, holding nothing but a run's outputs, and none of its inputs
    check_out_dir(out, inputs={"config": config_path, "map": cfg.map, "log": cfg.log, "bag": cfg.bag,
                               "truth": cfg.truth, "landmark map": cfg.landmarks.map, "plane map": cfg.planes.map})
    if args.write_bag and cfg.bag is None:
        raise MclError("--write-bag needs a bag input (--bag)")
    start_set = any(k in _START_KEYS for k in _set_keys(args.set))
    start_given = start_given or start_set
    if "filter.initial_pose=null" in replaced:
        print("mcl: note: the config's filter.initial_pose lies in its map, which this run replaces with its log: "
              "the run starts globally (--initial-pose X Y THETA tracks from a pose)", file=sys.stderr)
    if cfg.filter.global_localization and cfg.filter.initial_pose is not None:
        print(f"mcl: note: filter.global_localization is true, so filter.initial_pose "
              f"{list(cfg.filter.initial_pose)} is not used (--initial-pose X Y THETA tracks from a pose)", file=sys.stderr)
    if args.initial_std is not None and cfg.bag is None and (cfg.filter.global_localization
                                                             or cfg.filter.initial_pose is None):
        print("mcl: note: --initial-std is not used: the run starts globally (--initial-pose X Y THETA tracks from "
              "a pose)", file=sys.stderr)
    summary = run(cfg, out, progress=False if args.no_progress else None, initial_pose_override=start_given,
                  write_bag=args.write_bag, compile_note=True, fresh=not args.out,
                  start_given_as=(f"--initial-pose {' '.join(f'{v:g}' for v in args.initial_pose)}"
                                  if args.initial_pose is not None and not start_set else None))
    if args.json:
        print(summary_json(summary))
    if cfg.rerun.mode == "serve" and not summary["interrupted"] and not summary.get("late_signal"):
        # the servers live as long as this process: serve the finished recording until the user is done with it
        # Ctrl-C ends the wait even when the process was started with SIGINT ignored (a background job of a
        # non-interactive shell inherits that, and Python then installs no handler of its own)
        with contextlib.suppress(ValueError):  # not the main thread: the inherited handling stays
            signal.signal(signal.SIGINT, signal.default_int_handler)
        print("mcl: the run is over; serving its recording until Ctrl-C", file=sys.stderr)
        try:
            while True:
                time.sleep(3600)
        except KeyboardInterrupt:
            pass
    return EXIT_INTERRUPTED if summary["interrupted"] else 0


def set_threads(n: int) -> None:
    """numba's thread count for parallel kernels (MclError naming --threads when out of range)."""
    import numba

    top = numba.config.NUMBA_NUM_THREADS
    if not 1 <= n <= top:
        raise MclError(f"--threads: expected 1..{top} (the cores numba may use here), got {n}")
    numba.set_num_threads(n)


def _add_eval(sub) -> None:
    p = sub.add_parser(
        "eval",
        help="score a trajectory against a reference (ATE RMSE, max, heading RMSE, convergence time), or run "
             "a suite of datasets in every mode against the baseline (--suite)",
        description=(
            "Compare an estimated trajectory with a reference one (both TUM: t x y z qx qy qz qw, map frame). "
            "The estimate is interpolated at each reference time inside its span; no alignment is applied."
        ),
    )
    p.add_argument("estimate", nargs="?", help="estimated trajectory (TUM), e.g. runs/x/trajectory.tum")
    p.add_argument("reference", nargs="?", help="reference trajectory (TUM)")
    p.add_argument("--converged-within", type=float, metavar="M", help="error bound (m) for the convergence time (default 0.3)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    _add_suite_options(p)
    p.set_defaults(func=cmd_eval)


def _add_suite_options(p) -> None:
    """``mcl eval --suite``: a config over a corpus of datasets (mcl.suite)."""
    g = p.add_argument_group(
        "corpus evaluation (--suite)",
        "mcl eval --suite suites/real.yaml [--config C] [--seeds K] [--jobs J]: every dataset of the suite in each "
        "of its modes (tracking, global, kidnapped) with seeds 1..K, for the config and configs/baseline.yaml; "
        "prints the median and the worst over seeds; resumable (a rerun with the same --out skips finished runs)")
    g.add_argument("--suite", metavar="SUITE.yaml", help="suite file (see suites/); replaces ESTIMATE REFERENCE")
    g.add_argument("--config", help="config under test (default: configs/default.yaml)")
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key of the config under test (repeatable)")
    g.add_argument("--seeds", default="1", metavar="K",
                   help="seeds 1..K per run (default 1), or A-B: seeds A..B alone (fresh seeds; --seeds B on the same --out "
                        "then tables them all)")
    g.add_argument("--jobs", type=int, metavar="J", help="parallel runs (default: the cores)")
    g.add_argument("--out", help="output folder (default runs/suite-NAME); a rerun with the same folder resumes")
    g.add_argument("--cache", help="folder of the generated synthetic worlds (default OUT/worlds)")
    g.add_argument("--modes", metavar="M,...", help="only these modes: tracking,global,kidnapped")
    g.add_argument("--only", metavar="NAME,...", help="only these datasets (names, or patterns: 'corridor-*')")
    g.add_argument("--world", action="append", default=[], metavar="KEY=VALUE",
                   help="set a keyword of mcl simulate in every generated world of the suite (repeatable), e.g. "
                        "scan_rate=40 or range_max=8: the suite's worlds with your robot's laser (new worlds, cached "
                        "apart; real datasets unchanged)")
    g.add_argument("--start-offset", nargs=3, type=float, metavar=("DX", "DY", "DTHETA"),
                   help="move every tracking and kidnapped start pose by DX, DY m (map frame) and DTHETA rad: how "
                        "the config copes with a start clicked on a map (README, 'How good is your start pose?')")
    g.add_argument("--baseline", action=argparse.BooleanOptionalAction, default=True,
                   help="also run configs/baseline.yaml, the plain fixed-N filter (default on)")
    g.add_argument("--no-progress", action="store_true", help="no progress bar")


def cmd_eval(args) -> int:
    from mcl.evaluate import evaluate, format_eval, steps_back_paired
    from mcl.trajectory import read_tum

    if args.suite is not None:
        if args.estimate is not None:
            raise MclError("eval: --suite takes no ESTIMATE REFERENCE")
        given = [o for o, v in (("--json", args.json), ("--converged-within", args.converged_within is not None)) if v]
        if given:  # a suite's table, CSV and JSON files are its outputs; its convergence is lost_m's (README)
            raise MclError(f"eval: {', '.join(given)}: for ESTIMATE REFERENCE, not with --suite (its results are in "
                           "results.json and results.csv)")
        from mcl.suite import run_from_args

        return run_from_args(args)
    if args.estimate is None or args.reference is None:
        raise MclError("eval: expected ESTIMATE REFERENCE (two TUM files) or --suite SUITE.yaml")
    suite_only = [o for o, v in (("--config", args.config is not None), ("--set", args.set),
                                 ("--seeds", args.seeds != "1"), ("--jobs", args.jobs is not None),
                                 ("--out", args.out is not None), ("--cache", args.cache is not None),
                                 ("--modes", args.modes is not None), ("--only", args.only is not None),
                                 ("--world", args.world), ("--start-offset", args.start_offset is not None),
                                 ("--no-baseline", not args.baseline), ("--no-progress", args.no_progress)) if v]
    if suite_only:  # scoring two files runs nothing: a config or a seed given here was silently ignored
        raise MclError(f"eval: {', '.join(suite_only)}: for --suite, not with ESTIMATE REFERENCE (two files are "
                       "scored as they are)")
    if args.converged_within is None:
        args.converged_within = 0.3
    if not (args.converged_within > 0 and math.isfinite(args.converged_within)):  # (inf: converged at once)
        raise MclError(f"--converged-within: must be a positive number of metres, got {args.converged_within}")
    t_est, p_est = read_tum(args.estimate)
    t_ref, p_ref = read_tum(args.reference)
    paired = steps_back_paired(t_est, t_ref)
    for name, t, p in ((args.estimate, t_est, p_est), (args.reference, t_ref, p_ref)):
        if t.size == 0:
            raise MclError(f"{name}: no poses (an empty trajectory): nothing to score")
        if not paired:
            _warn_times(name, t, p)
    if paired:
        print(f"mcl: note: both trajectories' times go back {paired} time(s) (a clock set back): each run between "
              "is scored against the other file's run in the same place", file=sys.stderr)
    try:
        r = evaluate(t_est, p_est, t_ref, p_ref, converged_within=args.converged_within)
    except DataError:  # no reference pose inside the estimate's span: say which files and which spans
        raise MclError(f"{args.reference}: no pose lies within the time span of {args.estimate} (reference "
                       f"{t_ref.min():.3f}..{t_ref.max():.3f} s, estimate {t_est.min():.3f}..{t_est.max():.3f} s): "
                       "another clock or another dataset?") from None
    print(json.dumps(r, indent=2) if args.json else format_eval(r))
    return 0


def _warn_times(name, t, poses) -> None:
    """A warning line for a trajectory whose times go back or repeat (``mcl.evaluate.time_warnings``)."""
    from mcl.evaluate import time_warnings

    for _, said in time_warnings(name, t, poses):
        print(f"mcl: warning: {said}", file=sys.stderr)


def _command(sub, name: str, module, help: str, description: str, epilog: str | None = None) -> None:
    """A leaf command whose options come from ``module.add_arguments`` and which runs ``module.run_from_args``."""
    p = sub.add_parser(name, help=help, description=description, epilog=epilog,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    module.add_arguments(p)
    p.set_defaults(func=module.run_from_args)


def _group(sub, name: str, help: str, description: str):
    """A command with sub-commands (``mcl calibrate WHAT``); returns their subparsers."""
    p = sub.add_parser(name, help=help, description=description)
    return p.add_subparsers(dest="what", metavar="WHAT", required=True)


def _add_simulate(sub) -> None:
    from mcl import simulate

    _command(sub, "simulate", simulate,
             help="make a synthetic world: map + noisy log (CARMEN or a ROS bag) + exact truth",
             description="Draw an indoor world, drive a robot through it, and write map.yaml/map.pgm, log.clf,\n"
             "truth.tum and sim.yaml into OUTDIR.",
             epilog="examples:\n"
             "  mcl simulate data/demo --seed 7 --duration 70 --range-max 5 --kidnap-at 50 --dynamic-obstacles 4"
             "   # the bundled demo\n"
             "  mcl simulate runs/w --kind rooms --seed 3 --duration 90 # identical rooms: ambiguous\n"
             "  mcl simulate runs/w --kind hall --range-max 5.6 --fov 240 --beams 241   # short-range laser\n"
             "  mcl simulate runs/w --kind clutter --unmapped-furniture 25\n"
             "the 43 worlds of suites/synthetic.yaml: README, 'World kinds'")


def _add_calibrate(sub) -> None:
    from mcl import calibrate_motion, calibrate_mount, calibrate_sensor

    csub = _group(sub, "calibrate",
                  help="fit model parameters from a log (with reference poses, or for the mounting without); print "
                  "YAML to paste into a config",
                  description="Learn model parameters from a logged dataset: the sensor and motion models from one "
                  "whose reference trajectory is known, the laser's mounting from the odometry and the scans alone.")
    _command(
        csub, "sensor", calibrate_sensor,
        help="EM fit of the range sensor mixture (Prob. Rob. Table 6.2): beam or likelihood field",
        description=(
            "Fit z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short (beam model) or z_hit, z_rand, sigma_hit "
            "(likelihood field) by expectation-maximisation, from the scans at the reference poses (truth "
            "timestamps matched to scans within 1 ms). Prints a sensor: block ready to paste into a config."
        ),
        epilog="example:\n  mcl calibrate sensor --config configs/intel_lab.yaml --model likelihood_field",
    )
    _command(
        csub, "motion", calibrate_motion,
        help="maximum-likelihood fit of the odometry model's alpha1..alpha4 (Prob. Rob. Table 5.5)",
        description=(
            "Fit alpha1..alpha4 of the odometry motion model by maximum likelihood of the closed-form density over "
            "consecutive reference poses, with the log's odometry at the reference timestamps. The alphas describe "
            "the odometry error over the reference spacing. Prints a motion: block ready to paste into a config, "
            "each alpha with its standard error as a comment."
        ),
        epilog="example:\n  mcl calibrate motion --log data/demo/log.clf --truth data/demo/truth.tum",
    )
    _command(
        csub, "mount", calibrate_mount,
        help="the laser's pose on the robot (x, y, yaw) from the odometry and the scans (hand-eye, no reference)",
        description=(
            "Fit the laser's mounting on the robot from the log alone: the odometry check's 60 pairs of scans, each "
            "matched by ICP, set against the odometry's motion (planar hand-eye calibration: R(yaw) t_laser = "
            "t_robot + (R(turn) - I) m). The yaw needs the robot to drive, x and y need it to turn; the standard "
            "errors say how well each is pinned. Prints a sensor: block ready to paste into a config (each laser's "
            "fit, for fused lasers). mcl run fits the yaw by itself (sensor.mount_yaw), never x and y."
        ),
        epilog="examples:\n  mcl calibrate mount --log data/demo/log.clf\n"
        "  mcl calibrate mount --bag robot.mcap --set topics.scan=/front/scan",
    )


def _add_explore(sub) -> None:
    from mcl import explore

    esub = _group(sub, "explore",
                  help="look at a model: draw samples of the motion models into a PNG or a Rerun recording",
                  description="Draw samples of a model for a given pose and control, to see how its parameters shape it.")
    _command(
        esub, "motion", explore,
        help="sample the odometry or velocity model from one pose (the banana-shaped clouds)",
        description="Sample the odometry or velocity motion model from --pose; one panel per --alphas setting.",
        epilog=(
            "examples:\n"
            "  mcl explore motion --odom 0 0 0 1 0.2 0.5 --alphas 0.1,0.01,0.01,0.01 --alphas 0.01,0.1,0.01,0.01 --out m.png\n"
            "  mcl explore motion --velocity 1 0.5 1 --steps 5 --out v.rrd"
        ),
    )


def _add_tune(sub) -> None:
    from mcl import tune

    _command(sub, "tune", tune,
             help="search config values for the best score over a suite (Optuna; local processes or Ray)",
             description="Tune a config over a suite's datasets: each trial is the base config with the space's keys\n"
             "set to values Optuna's TPE proposes, scored like 'mcl eval --suite'. Study folder: best.yaml,\n"
             "trials.csv, plots/, summary.txt; Ctrl-C keeps the finished trials, --resume goes on.",
             epilog="examples:\n"
             "  mcl tune suites/real.yaml --space suites/tune-space.yaml --modes tracking --trials 50 --jobs 2\n"
             "  mcl tune suites/smoke.yaml --space S.yaml --objective rmse,particles --study runs/tune-pareto\n"
             "  mcl tune --resume runs/tune-real --trials 100\n"
             "  mcl tune --report runs/tune-real\n"
             "space file: README, 'Tuning a config'")


def _add_bag(sub) -> None:
    bsub = _group(sub, "bag", help="look into a ROS bag: topics, frames, and what mcl would use",
                  description="ROS 1 (.bag) and ROS 2 (.db3, .mcap, rosbag2 folder) recordings, read without ROS.")
    p = bsub.add_parser("info", help="topics, types, counts, duration, tf frames, and what mcl would use",
                        description="List a bag's topics (type, message count), its duration, the frames in /tf and "
                        "/tf_static, and the scan topics, odometry source, laser pose, map and initial pose mcl "
                        "would take from it with the given options (or why it cannot).")
    p.add_argument("bag", help="the bag")
    _bag_options(p)
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.set_defaults(func=cmd_bag_info)


def _bag_options(p) -> None:
    p.add_argument("--config", help="config whose topics: and frames: sections apply (default: the defaults)")
    p.add_argument("--scan-topic", metavar="TOPIC",
                   help="LaserScan/PointCloud2 topic, or 'all' to fuse them (topics.scan; default: /scan, else the "
                   "only one)")
    p.add_argument("--odom-topic", metavar="TOPIC",
                   help="nav_msgs/Odometry topic (or a pose topic in the odometry frame), 'tf' for odom -> base on "
                   "/tf, or 'laser' for the scans' own motion by scan matching (topics.odom)")
    p.add_argument("--odom-frame", metavar="FRAME", help="odometry frame (frames.odom, default odom)")
    p.add_argument("--base-frame", metavar="FRAME", help="robot frame (frames.base, default base_link)")


def _bag_config(args):
    from mcl.config import load_config

    overrides = []
    for key, value in (("topics.scan", args.scan_topic), ("topics.odom", args.odom_topic),
                       ("frames.odom", args.odom_frame), ("frames.base", args.base_frame)):
        if value is not None:
            overrides.append(f"{key}={json.dumps(value)}")
    return load_config(args.config, overrides)


def _add_log(sub) -> None:
    lsub = _group(sub, "log", help="look into a CARMEN log: messages, lasers, and what mcl would use",
                  description="CARMEN logs (plain or gzip): the messages mcl reads and those it skips.")
    p = lsub.add_parser("info", help="messages, lasers, duration, and what mcl would use",
                        description="Count a CARMEN log's messages (those mcl skips too), give its duration and each "
                        "laser stream (scans, beams, field of view, maximum range, mounting pose), and what a run "
                        "would read (the laser streams, the odometry) with the checks a run makes before it starts: "
                        "the beams that read the robot itself, the odometry and each laser's mounting, the scans' "
                        "stamps against the odometry's.",
                        epilog="examples:\n  mcl log info log.clf\n  mcl log info log.clf.gz --laser FLASER --json",
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log", help="the CARMEN log (.clf, .log, .gz)")
    p.add_argument("--config", help="config whose laser: and sensor: settings apply (default: the defaults)")
    p.add_argument("--laser", metavar="KIND",
                   help="laser stream(s) to read: auto, FLASER, RLASER, ROBOTLASER1, ... or several fused, "
                   "comma-separated (laser; default: auto)")
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.set_defaults(func=cmd_log_info)


def cmd_log_info(args) -> int:
    from mcl.config import load_config
    from mcl.datasets.loginfo import format_log_info, log_info
    from mcl.datasets.rosbag import is_bag

    if is_bag(args.log):
        raise MclError(f"{args.log}: a ROS bag, not a CARMEN log: mcl bag info {args.log}")
    cfg = load_config(args.config, [f"laser={args.laser}"] if args.laser else [])
    info = log_info(args.log, cfg.laser, cfg.sensor)
    print(json.dumps(info, indent=2) if args.json else format_log_info(info))
    return 0


def cmd_bag_info(args) -> int:
    from mcl.datasets.rosbag import bag_info, format_info, is_bag

    if not is_bag(args.bag) and Path(args.bag).is_file():
        raise MclError(f"{args.bag}: not a ROS bag (.bag, .db3, .mcap or a rosbag2 folder); a CARMEN log? "
                       f"mcl log info {args.bag}")
    cfg = _bag_config(args)
    info = bag_info(args.bag, cfg.topics, cfg.frames, cfg.sensor)
    print(json.dumps(info, indent=2) if args.json else format_info(info))
    return 0


def _add_convert(sub) -> None:
    p = sub.add_parser(
        "convert", help="a ROS bag to a CARMEN log, or a CARMEN log to a ROS bag (.bag, .db3, .mcap)",
        description="Convert between a ROS bag and a CARMEN log, keeping everything mcl uses: scan stamps, ranges, "
        "beam geometry, maximum range, odometry (pose and velocities) at each scan, laser mounting pose (a log's ODOM "
        "lines between scans are left out: a run on the bag cannot fit sensor.time_offset as one on the log can). A log "
        "becomes /scan (LaserScan), /odom (Odometry) and odom -> base_link on /tf (as a ROS robot records them: "
        "ROS AMCL and RViz need the /tf), base_link -> laser on /tf_static; a bag becomes ROBOTLASER1 + ODOM lines. "
        "Fused lasers are each kept, on their own mountings: a log's front and rear lasers (FLASER and RLASER, or "
        "ROBOTLASER1 and ROBOTLASER2) become /front/scan and /rear/scan; a bag's (two level lasers, or "
        "--scan-topic all) keep their topics, or become ROBOTLASER1 and ROBOTLASER2 in a log, which holds no more. "
        "The output appears only when complete.",
        epilog="examples:\n  mcl convert run.mcap run.clf\n  mcl convert log.clf log.mcap --odom topic\n"
        "  mcl convert log.clf log.bag --map map.yaml --initial-pose 1 2 0.5",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("src", help="bag (.bag, .db3, .mcap, rosbag2 folder) or CARMEN log")
    p.add_argument("out", help="output: .clf, .bag, .db3 or .mcap")
    _bag_options(p)
    p.add_argument("--odom", choices=["both", "topic", "tf"], default="both",
                   help="bag output: odometry as /odom and as odom -> base_link on /tf (both, the default), as /odom "
                   "only (topic) or on /tf only (tf)")
    p.add_argument("--mount", nargs=3, type=float, metavar=("X", "Y", "THETA"),
                   help="bag output: the laser's pose in a new base frame; the odometry becomes that base's")
    p.add_argument("--map", help="bag output: also write this map as /map (OccupancyGrid)")
    p.add_argument("--initial-pose", nargs=3, type=float, metavar=("X", "Y", "THETA"),
                   help="bag output: also write /initialpose (std 0.1 m, 0.1 m, 0.1 rad)")
    p.add_argument("--truth", help="bag output: also write this TUM trajectory as /ground_truth (PoseStamped)")
    p.set_defaults(func=cmd_convert)


def cmd_convert(args) -> int:
    import numpy as np

    from mcl.datasets.bagwrite import convert, kind_of_output

    cfg = _bag_config(args)
    grid = truth = initial = None
    if args.map:
        from mcl.maps import load_map

        grid = load_map(args.map)
    if args.truth:
        from mcl.trajectory import read_tum

        truth = read_tum(args.truth)
    if args.initial_pose:
        if not all(math.isfinite(v) for v in args.initial_pose):
            raise MclError(f"--initial-pose: expected finite X Y THETA, got {' '.join(map(str, args.initial_pose))}")
        if grid is not None and not grid.contains(*grid.world_to_cell(*args.initial_pose[:2])):
            raise MclError(f"--initial-pose: ({args.initial_pose[0]:g}, {args.initial_pose[1]:g}) lies outside the "
                           f"map {args.map}")
        initial = (np.array(args.initial_pose), np.diag([0.01, 0.01, 0.01]))
    if args.mount and not all(math.isfinite(v) for v in args.mount):  # a bag mcl itself refused ("no pose finite")
        raise MclError(f"--mount: expected finite X Y THETA, got {' '.join(map(str, args.mount))}")
    out = Path(args.out)
    if kind_of_output(out) == "clf":
        given = [o for o, v in (("--map", args.map), ("--truth", args.truth), ("--initial-pose", args.initial_pose),
                                ("--mount", args.mount), ("--odom", args.odom != "both")) if v]
        if given:  # (--mount and --odom were ignored without a word)
            raise MclError(f"{', '.join(given)}: written into a bag only; a CARMEN log ({out.name}) holds no map, "
                           "reference, initial pose, mounting of its own or odometry topics")
    if out.exists():
        raise MclError(f"{args.out}: exists already")
    if not out.parent.is_dir():  # a mistyped folder is not made
        raise MclError(f"{args.out}: the folder {out.parent} does not exist")
    from mcl.suite import TermAsInterrupt

    try:
        with TermAsInterrupt():  # SIGTERM (kill, timeout) stops it as Ctrl-C does: the output not left half-written
            n = convert(args.src, args.out, topics=cfg.topics, frames=cfg.frames, odom=args.odom, mount=args.mount,
                        grid=grid, initial=initial, truth=truth, echo=lambda m: print(m, file=sys.stderr),
                        truth_name=str(args.truth))
    except OSError as e:  # named by the user's path, not a temp file's
        raise MclError(f"{args.out}: cannot write: {e.strerror or e}") from None
    print(f"{args.out}: {n} scans")
    return 0


def package_version() -> str:
    """The installed distribution's version (pyproject.toml's, through importlib.metadata)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mcl")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed)"


def _add_config(sub) -> None:
    csub = _group(sub, "config", help="print the commented default config, the resolved config of a run, or the "
                  "config ROS AMCL parameters correspond to",
                  description="Configs: the documented defaults to start one from, what a run really used, and "
                  "the config that ROS AMCL parameters mean.")
    p = csub.add_parser("default", help="print configs/default.yaml: every key with its default and a comment",
                        description="Print the default config (the bundled demo's; every key, commented). Its "
                        "paths find the demo from anywhere.",
                        epilog="example:\n  mcl config default > my.yaml && mcl run my.yaml --set filter.particles=5000",
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(func=cmd_config_default)
    p = csub.add_parser("show", help="print the resolved config of a run folder or a config file (every key)",
                        description="Print the config a run used (RUN_DIR/config.yaml), or the one a config file "
                        "gives with the defaults filled in, paths made absolute and --set applied: what `mcl run` "
                        "would use.",
                        epilog="examples:\n  mcl config show runs/20261123-101500\n"
                        "  mcl config show configs/intel_lab.yaml --set sensor.model=beam",
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("path", metavar="RUN_DIR|CONFIG", help="a run folder (its config.yaml) or a config file")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key (repeatable)")
    p.set_defaults(func=cmd_config_show)
    p = csub.add_parser(
        "from-amcl", help="print the mcl config that ROS AMCL parameters (ROS 1 amcl, nav2_amcl) correspond to",
        description=_wrap(
            "Read a tuned ROS AMCL parameter file and print the mcl config keys its parameters correspond to, "
            "each commented with the AMCL parameter it came from; only those keys, so the output runs as it is "
            "(mcl run OUT.yaml --bag B) or merges into a config. PARAMS is a nav2 params file (the amcl node's "
            "ros__parameters among the other nodes', or the bare mapping), ROS 1 amcl parameters as YAML (flat or "
            "under the node's name), or a ROS 1 .launch file with <node pkg=\"amcl\"> (its <param>, <rosparam> "
            "and scan/map <remap>; $(arg ...), $(find ...), if= and unless= resolved, on the node and its <group>s "
            "too: the first amcl node launched with the args' defaults is read). What it maps, following "
            "AMCL's sources: particle counts "
            "and KLD (kld_z/pf_z is a normal quantile: kld_delta = 1 - Phi(z)), the odometry alphas (diff-corrected "
            "and nav2's model are mcl's variance form; ROS 1's diff and the omni models are warned about), the "
            "laser model and its weights (AMCL's unnormalised Gaussian made a density), beam skipping, update "
            "gating, augmented-MCL recovery, the start pose, frames and topics. Parameters with no mcl "
            "counterpart are listed at the end; an unknown name is a warning (with a did-you-mean). The output is "
            "checked as mcl loads a config: a value mcl refuses is an error naming the AMCL parameter."),
        epilog="examples:\n  mcl config from-amcl nav2_params.yaml -o amcl.yaml && mcl run amcl.yaml --bag run.mcap\n"
        "  mcl config from-amcl amcl_diff.launch\nmapping table: README, 'Coming from ROS AMCL'",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("params", metavar="PARAMS", help="AMCL parameters: nav2 params YAML, ROS 1 amcl YAML or .launch")
    p.add_argument("-o", "--out", metavar="OUT.yaml", help="write the config here (default: print it)")
    p.set_defaults(func=cmd_config_from_amcl)


def cmd_config_default(args) -> int:
    p = _project_default_config()
    if p is None:
        raise MclError("configs/default.yaml: not found in the repository nor in the installed package")
    sys.stdout.write(p.read_text(encoding="utf-8"))
    return 0


def cmd_config_show(args) -> int:
    from mcl.config import dump_config, load_config

    path = Path(args.path)
    if path.is_dir():
        if not (path / "config.yaml").is_file():
            raise MclError(f"{path}: no config.yaml (not a run folder?)")
        path = path / "config.yaml"
    # the config mcl run would use with these --set: a new log drops the config's truth and start pose
    sys.stdout.write(dump_config(load_config(path, _data_replaced(path, args.set) + list(args.set))))
    return 0


def _wrap(text: str) -> str:
    """A long description in lines of at most 100 characters (for RawDescriptionHelpFormatter, which keeps the
    epilog's examples as they are written)."""
    import textwrap

    return "\n".join(textwrap.wrap(text, 100, break_on_hyphens=False))


def cmd_config_from_amcl(args) -> int:
    from mcl.amcl_params import convert

    if args.out is not None and Path(args.out).resolve() == Path(args.params).resolve():
        raise MclError(f"-o {args.out}: that is the AMCL parameter file itself")
    if args.out is not None and not Path(args.out).resolve().parent.is_dir():
        raise MclError(f"-o {args.out}: the folder {Path(args.out).parent} does not exist")
    result = convert(args.params)
    for w in result.warnings:
        print(f"mcl: warning: {w}", file=sys.stderr)
    if args.out is None:
        sys.stdout.write(result.text)
        return 0
    out = Path(args.out)
    tmp = out.with_name(out.name + ".partial")
    try:
        tmp.write_text(result.text, encoding="utf-8")
        os.replace(tmp, out)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise MclError(f"-o {args.out}: cannot write: {e.strerror or e}") from None
    print(f"{args.out}: {len(result.keys)} keys", file=sys.stderr)
    return 0


# options and positionals that name a file or folder: `~` expanded (bash leaves it alone after `--out=`), an empty
# value refused (`--log ''` read the current folder as the log)
_PATH_OPTIONS = {"--config", "--map", "--log", "--bag", "--truth", "--out", "-o", "--suite", "--cache", "--space",
                 "--study"}
_PATH_POSITIONALS = {"config", "estimate", "reference", "outdir", "suite", "bag", "log", "src", "out", "path",
                     "params"}


def _path_arg(value: str) -> str:
    if not value.strip():
        raise argparse.ArgumentTypeError("an empty path")
    if any(c in value for c in "\n\r\0"):
        raise argparse.ArgumentTypeError(f"not a usable path: {value!r}")
    return os.path.expanduser(value)


def _leaf_parsers(parser: argparse.ArgumentParser):
    """Every parser of a command that runs (``mcl run``, ``mcl calibrate sensor``), with its subparsers' parents."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield parser
    for a in subs:
        for child in dict.fromkeys(a.choices.values()):
            yield from _leaf_parsers(child)


def _finish(parser: argparse.ArgumentParser) -> None:
    """What every command's parser shares: path arguments through ``_path_arg``, descriptions wrapped at 100
    characters (RawDescriptionHelpFormatter keeps them as written: `mcl convert --help` had an 867-character line),
    and the parser itself in the parsed arguments (``main`` names an unknown option in its usage)."""
    import textwrap

    def walk(p):
        if p.description and isinstance(p.formatter_class, type) and issubclass(
                p.formatter_class, argparse.RawDescriptionHelpFormatter):
            p.description = "\n".join(textwrap.fill(line, 100, break_on_hyphens=False) if len(line) > 100 else line
                                      for line in p.description.split("\n"))
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for child in dict.fromkeys(a.choices.values()):
                    walk(child)
            elif a.type is None and a.nargs != 0 and (
                    set(a.option_strings) & _PATH_OPTIONS or (not a.option_strings and a.dest in _PATH_POSITIONALS)):
                a.type = _path_arg

    walk(parser)
    for leaf in _leaf_parsers(parser):
        leaf.set_defaults(_parser=leaf)


def _unknown(args, extra: list[str], argv: list[str] | None) -> None:
    """An option no command knows: the command's own usage, and the option it was probably meant to be (argparse
    3.11 printed `mcl`'s top-level usage, with no suggestion)."""
    import difflib

    leaf = getattr(args, "_parser", None)
    words = sys.argv[1:] if argv is None else list(argv)
    command = getattr(args, "command", None)
    if leaf is None or command not in words or words.index(extra[0]) < words.index(command):
        return  # before the command (`mcl --bogus run`): mcl's own usage says it
    options = [o for a in leaf._actions for o in a.option_strings]
    hints = [h for x in extra if x.startswith("--")
             for h in difflib.get_close_matches(x.split("=", 1)[0], options, n=1)]
    leaf.error(f"unrecognized arguments: {' '.join(extra)}" + (f" (did you mean {', '.join(hints)}?)" if hints else ""))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mcl",
        description="Monte Carlo localization of 2D mobile robots: replay logged odometry and laser scans against an "
        "occupancy-grid map, write the trajectory and a Rerun recording of every filter step.",
        epilog="Run 'mcl COMMAND --help' for the options of a command.",
    )
    parser.add_argument("--version", action="version", version=f"mcl {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_run(sub)
    _add_eval(sub)
    _add_simulate(sub)
    _add_calibrate(sub)
    _add_explore(sub)
    _add_tune(sub)
    _add_bag(sub)
    _add_log(sub)
    _add_convert(sub)
    _add_config(sub)
    _finish(parser)
    return parser


@contextlib.contextmanager
def _clean_warnings():
    """While a command runs, mcl's own warnings (MclWarning) print as one line, ``mcl: warning: <message>``, with
    no module path or source line; tqdm.write keeps a running progress bar intact. Other warnings print as Python
    prints them, and the library itself keeps plain ``warnings.warn`` (pytest.warns, catch_warnings)."""
    saved = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, MclWarning):
            return saved(message, category, filename, lineno, file, line)
        from tqdm import tqdm

        tqdm.write(f"mcl: warning: {message}", file=file or sys.stderr)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = saved


def main(argv: list[str] | None = None) -> int:
    try:  # Ctrl-C while the parser is built (its imports take a moment): the one line below, not a traceback
        parser = build_parser()
        if "_ARGCOMPLETE" in os.environ:  # the shell asks for completions (pip install 'mcl[completion]')
            with contextlib.suppress(ImportError):
                import argcomplete

                argcomplete.autocomplete(parser, exit_method=sys.exit)
        args, extra = parser.parse_known_args(argv)
        if extra:
            _unknown(args, extra, argv)
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
    except KeyboardInterrupt:
        print("mcl: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    if args.command is None:
        parser.print_help()
        return 0
    try:
        with _clean_warnings():
            status = int(args.func(args) or 0)
            sys.stdout.flush()  # here, not at exit: a reader that left is then the BrokenPipeError below
            return status
    except MclError as e:
        print(f"mcl: error: {e}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("mcl: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError as e:
        if e.filename is None:  # stdout's reader left (`mcl log info L | head -1`): quiet, as cat and grep are
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error as Python exits
            return EXIT_BROKEN_PIPE
        print(f"mcl: error: {e.filename}: {e.strerror or e}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as e:  # a file mcl could not write (a full disk, a folder made read-only mid-run): one line
        where = f"{e.filename}: " if e.filename else ""
        print(f"mcl: error: {where}{e.strerror or e}", file=sys.stderr)
        return EXIT_ERROR
    except MemoryError:  # options that pass their checks but need more memory than there is
        print(f"mcl: error: out of memory in mcl {args.command} (smaller inputs or options)", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())

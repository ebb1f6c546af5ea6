"""``fusiongs deblur SCENE -o OUT``: blurry frames + events -> sharp frames, video and 3DGS model."""

from __future__ import annotations

import argparse

HELP = "fit a 3DGS scene and trajectory to blurry frames and events; write sharp frames and video"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene folder (scene.json; see docs/scene-format.md), or a folder of scene "
                                 "folders (a dataset: each is deblurred into OUT/<name>/, with one table "
                                 "in OUT/summary.json)")
    p.add_argument("-o", "--output", "--out", dest="out", default=None, help="output folder (required)")
    p.add_argument("--config", default=None,
                   help="YAML config: a path or a preset name (deblur, deblur_fast, deblur_quality, "
                        "event_only); default: the built-in defaults = deblur")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--calibration", default=None, metavar="FILE",
                   help="calibration.json from `fusiongs calibrate` (default: estimate the same way)")
    p.add_argument("--holdout", default=None, metavar="K",
                   help="leave every K-th frame out of training (frames i with i %% K == K-1, never the "
                        "first or last) and score the predictions of those frames against the real ones "
                        "(OUT/heldout.json); K >= 2, 0 = off (default)")
    p.add_argument("--print-config", action="store_true",
                   help="print the merged config (defaults, --config, overrides) as YAML and exit")
    p.add_argument("--jobs", type=int, default=0, metavar="N",
                   help="a dataset, or a recording in time chunks (chunk.seconds): pieces deblurred "
                        "at once, each in its own process (default 0: one per CPU core)")
    p.add_argument("--executor", default="local", choices=("local", "serial", "dask"),
                   help="a dataset or chunks: where the pieces run: local worker processes (default), "
                        "one after another in this process, or a Dask cluster "
                        "(pip install -e \".[cluster]\")")
    p.add_argument("--address", default=None, metavar="tcp://HOST:PORT",
                   help="--executor dask: the scheduler of a running Dask cluster whose workers see "
                        "the same files (default: start a local cluster of --jobs workers)")
    p.add_argument("overrides", nargs="*", metavar="key=value",
                   help="config overrides, e.g. optim.iterations=500 events.loss=band")


def run(args: argparse.Namespace) -> int:
    from fusiongs.errors import InputError
    from fusiongs.pipeline.deblur import resolve_config, run_deblur

    if args.print_config:
        from fusiongs.configs.load import to_yaml

        print(to_yaml(resolve_config(args.config, args.overrides)), end="")
        return 0
    if args.out is None:
        raise InputError("command line", "-o/--output", "an output folder")
    if args.jobs < 0:
        raise InputError("command line", "--jobs", "a number of workers >= 0 (0: one per core)", args.jobs)
    if args.address and args.executor != "dask":
        raise InputError("command line", "--address", "--executor dask with a scheduler address",
                         args.address)
    from pathlib import Path

    from fusiongs.pipeline.dataset import longer_than_a_chunk, run_dataset

    if Path(args.scene).is_dir() and not (Path(args.scene) / "scene.json").exists():  # a dataset
        run_dataset(args.scene, args.out, config=args.config, overrides=args.overrides,
                    calibration=args.calibration, holdout=args.holdout, resume=args.resume,
                    jobs=args.jobs, executor=args.executor, address=args.address)
        return 0
    if longer_than_a_chunk(args.scene, args.config, args.overrides):  # in time chunks
        from fusiongs.pipeline.chunks import run_chunked

        run_chunked(args.scene, args.out, config=args.config, overrides=args.overrides,
                    calibration=args.calibration, holdout=args.holdout, resume=args.resume,
                    jobs=args.jobs, executor=args.executor, address=args.address)
        return 0
    run_deblur(args.scene, args.out, config=args.config, overrides=args.overrides, resume=args.resume,
               calibration=args.calibration, holdout=args.holdout)
    return 0

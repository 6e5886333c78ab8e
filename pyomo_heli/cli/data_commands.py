"""Commands on flight-test folders and settings files: ``generate-data``, ``check-data`` and ``schema``."""
from __future__ import annotations

from pathlib import Path

from .folders import _check_out_dir
from .options import UserError

def cmd_generate_data(args) -> int:
    from ..flighttest.generate import generate_from_file

    if args.seed is not None and args.seed < 0:
        raise UserError(f"option --seed must be an integer >= 0, got {args.seed}")
    _check_out_dir(args.out)
    replaced = (Path(args.out) / "manifest.json").is_file()
    out = generate_from_file(args.config, args.out, seed=args.seed, force=args.force)
    print(f"wrote synthetic flight test to {out}" + (" (replacing the flight test that was there)" if replaced else ""))
    return 0


def cmd_schema(args) -> int:
    from ..settings import schema_text, write_schemas

    if args.out_dir and args.kind:  # --out-dir writes every kind: a kind given too would be dropped
        raise UserError(f"give a config kind ({args.kind}) or --out-dir (every kind), not both")
    if args.out_dir:
        for path in write_schemas(args.out_dir):
            print(path)
    elif args.kind:
        print(schema_text(args.kind), end="")
    else:
        raise UserError("schema: give a config kind or --out-dir")
    return 0


def cmd_check_data(args) -> int:
    from ..dataset.cli import check_data

    d = Path(args.directory)
    if d.exists() and not d.is_dir():
        raise UserError(f"{args.directory} is a file, expected a dataset folder")
    if (d / "manifest.json").is_dir():
        raise UserError(f"{d / 'manifest.json'} is a directory, expected a file")
    return check_data(args.directory)


"""CLI wiring for ``mpc-actuator import MAPPING --out DIR`` (hooked into harness/cli.py by the integrator).

Usage in ``harness/cli.py``::

    from harness.data.labimport import add_import_subcommand, run_import
    add_import_subcommand(subparsers)          # registers "import" with func=run_import
    ...
    return args.func(args)                     # or: if args.command == "import": return run_import(args)
"""
from __future__ import annotations

import sys

from harness.data.labimport.errors import LabImportError
from harness.data.labimport.importer import import_lab_files

__all__ = ["add_import_subcommand", "run_import"]


def add_import_subcommand(subparsers):
    """Add the ``import`` subcommand to an argparse ``subparsers`` object; returns its parser.

    Examples
    --------
    >>> import argparse
    >>> ap = argparse.ArgumentParser(prog="mpc-actuator")
    >>> p = add_import_subcommand(ap.add_subparsers(dest="command"))
    >>> a = ap.parse_args(["import", "map.json", "--out", "ds"])
    >>> (a.command, a.mapping, a.out, a.overwrite)
    ('import', 'map.json', 'ds', False)
    """
    p = subparsers.add_parser(
        "import", help="import lab files (CSV/TSV, LVM, TDMS, MAT) into an mpc-actuator-data/1 dataset",
        description="Convert lab exports into the dataset format, as described by a JSON mapping file "
                    "(schema: harness/data/labimport/mapping.py). Input files are only read; the dataset is "
                    "written into the new or empty folder given by --out.")
    p.add_argument("mapping", help="mapping file (JSON): which file and column is which, sample metadata")
    p.add_argument("--out", required=True, help="output folder (new or empty)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an earlier synthetic import in --out (measured data are never overwritten)")
    p.set_defaults(func=run_import)
    return p


def run_import(args) -> int:
    """Run the ``import`` subcommand; prints the dataset folder. Returns the exit code (2 on a
    LabImportError, whose message names file, line and column, printed to stderr)."""
    try:
        out = import_lab_files(args.mapping, args.out, overwrite=bool(getattr(args, "overwrite", False)))
    except LabImportError as e:
        print(f"mpc-actuator import: error: {e}", file=sys.stderr)
        return 2
    print(f"wrote dataset {out}")
    return 0

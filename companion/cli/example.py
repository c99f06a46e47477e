"""``companion example NAME``: the files shipped in the package (default configuration, sample noise model)."""

from __future__ import annotations

import argparse

from companion.examples import EXAMPLES

DESCRIPTION = """\
Print one of the files shipped with companion, or write it to --out: a starting point that works
wherever companion is installed (a wheel has no source tree).

  config  every configuration key with its default, with comments (edit, then pass --config FILE to
          run, inspect, analyze, gap or compensate)
  model   a noise model (rate_hz and per-axis effects in SI units) for simulate and gap --model"""

EPILOG = """\
examples:
  companion example config --out my.yaml            # then: companion run --source ... --config my.yaml
  companion example model --out model.yaml
  companion simulate model.yaml --duration 600 --out sim.tlog --seed 1
  companion example model | grep white_noise

exit status: 0 done, 2 usage error or an --out that cannot be written."""


def register(subparsers) -> None:
    names = ", ".join(EXAMPLES)
    p = subparsers.add_parser("example", help=f"print a shipped example file ({names})",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", choices=tuple(EXAMPLES), metavar="NAME", help=f"one of: {names}")
    p.add_argument("--out", metavar="FILE", help="write it to FILE instead of standard output (not overwritten "
                                                 "silently: an existing FILE is an error)")
    p.set_defaults(func=run)


def run(args) -> int:
    import os

    from companion.cli.output import check_output_path, write_text
    from companion.errors import CompanionError
    from companion.examples import text

    if args.out is None:
        print(text(args.name), end="")
        return 0
    check_output_path(args.out, "--out")
    if os.path.exists(args.out):
        raise CompanionError(f"--out {args.out}: already exists (remove it or give another name)")
    write_text(args.out, text(args.name), f"the {args.name} example")
    print(f"wrote {args.out} ({EXAMPLES[args.name][1]})")
    return 0

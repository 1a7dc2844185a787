"""``fault-monitor envelope POINT.toml ... --schedule airspeed --out ENV.toml``: single-point plants -> an envelope.

Argument parsing and printing only: the assembly (each point's place from its operating point, sorted by the
schedule, validated) is ``monitor.model.envelope.assemble_envelope``; each point's signal map is checked by the
link layer's parser here, as ``run`` will read it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "envelope",
        help="assemble single-point plants identified at several operating points into an envelope plant file",
        description=(
            "Assemble single-point plant files (each what `fault-monitor identify` writes from one leg at one\n"
            "operating point) into one envelope plant file: each point's place in the schedule is its\n"
            "[signals] operating_point's value of the --schedule signals, and the points are sorted by it.\n"
            "The points must share h, the delay interval, their dimensions and signal names.\n"
            "Then: fault-monitor design --plant ENV.toml --out GAINS.toml (per-point gains and one certificate\n"
            "over the envelope) and fault-monitor verify --plant ENV.toml --gains GAINS.toml."
        ),
        epilog="Example: fault-monitor envelope slow.toml cruise.toml fast.toml --schedule airspeed --out env.toml",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("plants", nargs="+", metavar="POINT.toml", help="single-point plant files, one per point")
    parser.add_argument(
        "--schedule",
        required=True,
        action="append",
        metavar="SIGNAL",
        help="a signal that schedules (in every point's operating point), e.g. airspeed; give it twice for two",
    )
    parser.add_argument("--out", required=True, metavar="ENV.toml", help="the envelope plant file to write")
    parser.add_argument("--name", help="the envelope's name (default: the output file's stem)")
    parser.add_argument("--description", default="", help="a line describing the envelope")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.errors import UserError
    from monitor.files import write_text_atomically
    from monitor.link.signals import signals_for_plant
    from monitor.model.envelope import assemble_envelope, parse_envelope, point_name
    from monitor.model.plant import load_plant

    points = []
    named: dict[str, str] = {}
    for path in args.plants:
        if not Path(path).is_file():
            raise UserError(f"plant file '{path}' is not a readable file")
        plant = load_plant(path)
        signals_for_plant(plant)  # the map run will read: one line naming what is wrong with it
        name = point_name(Path(path).stem)
        if name in named:
            raise UserError(f"{path} and {named[name]} give the same point name '{name}': rename one of the files")
        named[name] = path
        points.append((name, plant))
    out = Path(args.out)
    title = args.name or out.stem
    text = assemble_envelope(points, args.schedule, title, args.description)
    envelope = parse_envelope(text, source=str(out))
    try:
        write_text_atomically(out, text)
    except OSError as exc:
        raise UserError(f"{out}: cannot write the envelope: {exc}") from None
    for point in envelope.points:
        place = ", ".join(f"{s} {point.at[s]:g}" for s in envelope.schedule)
        print(f"point      {point.name:<16} {place}   ({named[point.name]})")
    print(
        f"wrote      {out}: envelope '{envelope.name}', {len(envelope.points)} points scheduled by "
        f"{', '.join(envelope.schedule)}; h = {envelope.h:g} s, tau in [{envelope.tau_min:g}, {envelope.tau_max:g}] s"
    )
    return 0

"""Write a probe library of procedural door cabinets only, for development runs on `--assets DIR`.

The built-in storage category is half chests of drawers, and its door cabinets span every size in
``StorageRanges``. This writes door cabinets alone, optionally narrowed to one corner of those
ranges (for example a small single door, the size of a safe's), from a library seed other than the
benchmark's (0), so none is a val or test instance. Every object is put in the ``val`` split of the
probe folder, which is what `wpbench run --assets DIR` scores by default; ``--split train`` puts them
in ``train`` instead, for `wpbench data generate --assets DIR --split train`.

    python scripts/door_cabinet_probe.py --out runs/probe/small --width 0.50 0.58 --height 0.65 0.75
    wpbench run --policy wp --task open-door --assets runs/probe/small --episodes 18 --executor ideal
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from wpbench.assets.procedural import generate as library
from wpbench.assets.procedural import storage


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder to write (must not exist)")
    parser.add_argument("--count", type=int, default=6, help="cabinets to write")
    parser.add_argument("--seed", type=int, default=7, help="library seed; 0 is the benchmark's own")
    parser.add_argument("--width", type=float, nargs=2, help="carcass width range, m")
    parser.add_argument("--height", type=float, nargs=2, help="carcass height range above the base, m")
    parser.add_argument("--base", type=float, nargs=2, help="plinth and leg height range, m")
    parser.add_argument("--split", choices=("val", "train"), default="val",
                        help="split to put every cabinet in: val to score them, train to generate training data from them")
    args = parser.parse_args()
    if args.seed == 0:
        parser.error("--seed 0 draws the benchmark's own instances; choose another seed")
    if args.out.exists():
        parser.error(f"{args.out} exists; choose a new folder")

    ranges = replace(storage.StorageRanges(), door_cabinet_share=1.0)
    if args.width:
        ranges = replace(ranges, width=tuple(args.width))
    if args.height:
        ranges = replace(ranges, height=tuple(args.height))
    if args.base:
        ranges = replace(ranges, plinth_height=tuple(args.base), leg_height=tuple(args.base))

    # generate_object builds through the BUILDERS table; point storage at door cabinets of these ranges.
    library.BUILDERS["storage"] = lambda rng, object_id: storage.build_door_cabinet(rng, object_id, ranges)
    ids = [library.generate_object("storage", index, args.out, seed=args.seed, split=args.split).object_id
           for index in range(args.count)]
    splits = {"train": [], "val": [], "test": []}
    splits[args.split] = ids
    (args.out / "split.json").write_text(json.dumps(splits, indent=2) + "\n")
    print(f"wrote {len(ids)} door cabinets to {args.out}")


if __name__ == "__main__":
    main()

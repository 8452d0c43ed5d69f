"""The generated module of every library system, for refactoring the code generator safely.

A change to ``biped_opt/codegen`` that only reorganises the generator (moving functions between
modules, renaming its helpers) must leave every generated module byte for byte the same: same
text, same source key, same compiled code and numbers. This script renders each library
system's simulator module and scene module (and, with ``--user``, the test suite's own system
files) and prints name -> source key; ``--save F`` writes them, ``--against F`` compares with a
saved run and exits non-zero on any difference.

    python -m bench.source_keys --save before.json   # on the old code
    python -m bench.source_keys --against before.json  # on the new code

Rendering is symbolic work only (nothing compiles): about a minute on 2 cores, most of it the
humanoid g1 and the quadruped.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

from biped_opt.codegen.render import render, source_key
from biped_opt.codegen.scene import render_scene
from biped_opt.systems.derive import derive
from biped_opt.systems.description import System
from biped_opt.systems.files import load_system
from biped_opt.systems.library import biped, chain, quadruped, rocking_bar, walker
from biped_opt.systems.library.robots import bolt, g1, solo12
from biped_opt.systems.library.smooth_biped import smooth_biped
from biped_opt.systems.library.soft_rocking_bar import soft_rocking_bar

USER_SYSTEMS = Path(__file__).resolve().parent.parent / "tests" / "simulation" / "user"


def library() -> dict[str, Callable[[], System]]:
    """Every system the library builds, each size and law of the walker and chain included."""
    systems: dict[str, Callable[[], System]] = {
        "biped": biped, "rocking_bar": rocking_bar, "smooth_biped": smooth_biped,
        "soft_rocking_bar": soft_rocking_bar, "quadruped": quadruped,
        "solo12": solo12, "bolt": bolt, "g1": g1}
    for n in (2, 3, 4, 5, 8):
        for law in ("coupled", "decoupled"):
            systems[f"walker{n}_{law}"] = lambda n=n, law=law: walker(n, law)
    for k in (1, 2, 3, 4):
        systems[f"chain{k}"] = lambda k=k: chain(k)
    return systems


def keys(*, user: bool) -> dict[str, str]:
    out: dict[str, str] = {}
    factories = library()
    if user:
        for path in sorted(USER_SYSTEMS.glob("*.py")):
            if not path.name.startswith(("__", "reference")):
                factories[path.name] = lambda path=path: load_system(str(path))
    for name, factory in factories.items():
        system = factory()
        out[name] = source_key(render(derive(system)))
        out[f"{name}/scene"] = source_key(render_scene(system))
        print(f"{name:24s} {out[name]}  scene {out[f'{name}/scene']}", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--user", action="store_true", help="also the test suite's system files")
    ap.add_argument("--save", type=Path, help="write the keys to this JSON file")
    ap.add_argument("--against", type=Path, help="compare with the keys of a saved run")
    args = ap.parse_args(argv)
    found = keys(user=args.user)
    if args.save:
        args.save.write_text(json.dumps(found, indent=1) + "\n")
    if args.against:
        saved = json.loads(args.against.read_text())
        changed = sorted(k for k in saved.keys() | found.keys() if saved.get(k) != found.get(k))
        for name in changed:
            print(f"changed: {name}: {saved.get(name)} -> {found.get(name)}")
        print(f"{len(found) - len(changed)} of {len(found)} modules unchanged")
        return 1 if changed else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""CTest `api.headers`: docs/api.md names every installed header (`tsah/room/x.hpp`, `anim/x.hpp`,
`tsah_cuda/x.hpp` in backticks) and no header that does not exist, so the page cannot drift from
what `cmake --install` puts under include/."""
import pathlib
import re
import sys

root = pathlib.Path(__file__).resolve().parents[1]
include_dirs = [root / "libanim/include", root / "libtsah/include", root / "cuda_kernels/include"]
installed = {str(p.relative_to(d)) for d in include_dirs for p in d.rglob("*") if p.suffix in (".hpp", ".h")}
doc = (root / "docs/api.md").read_text()
named = set(re.findall(r"`((?:tsah|anim|tsah_cuda)/[A-Za-z0-9_/]+\.hpp)`", doc))
problems = [f"docs/api.md: installed header {h} is not listed" for h in sorted(installed - named)]
problems += [f"docs/api.md: lists {h}, which is not an installed header" for h in sorted(named - installed)]
for line in problems:
    print(line)
sys.exit(1 if problems else 0)

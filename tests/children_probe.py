"""A child for tests/test_children.py: prints where it runs and how, then, with ``wait``, calls
:func:`biped_opt.children.limit_background` and sleeps (its time limit ends it)."""

from __future__ import annotations

import json
import os
import sys
import time

if __name__ == "__main__":
    print(json.dumps({"cwd": os.getcwd(), "nice": os.nice(0), "path0": sys.path[0],
                      "safe_path": bool(getattr(sys.flags, "safe_path", False))}), flush=True)
    if sys.argv[1:] == ["wait"]:
        from biped_opt.children import limit_background

        limit_background()
        time.sleep(60.0)

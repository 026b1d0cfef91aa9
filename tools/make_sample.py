#!/usr/bin/env python3
"""Write the bundled demo take (deterministic): python tools/make_sample.py samples/demo_take.c3d"""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "addon"))

from mocap_autolabel.core.formats.c3d import write_c3d  # noqa: E402
from mocap_autolabel.core.synth.sample import sample_take  # noqa: E402

if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else "samples/demo_take.c3d"
    write_c3d(sample_take(), out)
    print(f"wrote {out}")

"""Recording throughput for BipedState and the size of a 201-point optimal sweep (issue 7).

Prints JSON: messages/s and MB/s of ``SweepWriter.write_states`` (vectorised, a realistic
trajectory), of the per-message path ``SweepWriter.write`` (rosbags serialization), and the size of
a file holding a 201-point sweep with full state trajectories at 200 Hz. The sweep's trajectories
are real simulations at the touchdown problem's optimal-policy region (fixed inputs (0.5, 0.5): the
cost of solving 201 optimisations is not what is measured; the file holds the same messages a
recorded optimal sweep does: states at 200 Hz, contact modes, SweepPoints).

Run: ``python bench/record_throughput.py``. Acceptance: >= 100k msg/s; file < 10 MB.
"""

from __future__ import annotations

import io
import json
import time

import numpy as np

from biped_opt import simulate
from biped_opt.piecewise import theta_grid
from biped_opt.record import SweepWriter

NS = 1_000_000_000


def _states_rate(samples: np.ndarray, repeats: int) -> dict:
    buf = io.BytesIO()
    start = time.perf_counter()
    with SweepWriter(buf) as w:
        for k in range(repeats):
            w.write_states(maneuver="touchdown", theta0=0.05, samples=samples,
                           stamp_offset_ns=k * 10 * NS)
    seconds = time.perf_counter() - start
    n = repeats * samples.shape[0]
    raw = n * 196
    return {"messages": n, "seconds": seconds, "msg_per_s": n / seconds,
            "payload_MB_per_s": raw / seconds / 1e6, "file_MB": buf.tell() / 1e6}


def _per_message_rate(samples: np.ndarray, count: int) -> dict:
    buf = io.BytesIO()
    rows = [samples[k % samples.shape[0]] for k in range(count)]
    start = time.perf_counter()
    with SweepWriter(buf) as w:
        for k, r in enumerate(rows):
            ns = k * 5_000_000
            w.write("/biped/state", {
                "header": {"stamp": {"sec": ns // NS, "nanosec": ns % NS}, "frame_id": "biped"},
                "maneuver": "touchdown", "theta0": 0.05, "t": r[0], "q": r[1:8],
                "qdot": r[8:15], "contact_mode": int(r[15]), "contact_force": r[16:18]}, ns)
    seconds = time.perf_counter() - start
    return {"messages": count, "seconds": seconds, "msg_per_s": count / seconds,
            "payload_MB_per_s": count * 196 / seconds / 1e6}


def _sweep_size(num: int = 201) -> dict:
    buf = io.BytesIO()
    offset, states = 0, 0
    with SweepWriter(buf, metadata={"maneuver": "touchdown", "num": str(num),
                                    "optimal": "True"}) as w:
        for th in theta_grid(-0.2, 0.2, num):
            tr = simulate("touchdown", th, (0.5, 0.5), sample_dt=0.005)
            states += w.write_states(maneuver="touchdown", theta0=th, samples=tr.samples,
                                     stamp_offset_ns=offset)
            for t, mode in zip([0.0, *tr.event_times], tr.mode_sequence):
                ns = offset + int(t * NS)
                w.write("/biped/contact_mode", {"header": {"stamp": {"sec": ns // NS,
                        "nanosec": ns % NS}}, "mode": int(mode)}, ns)
            w.write("/biped/sweep", {"maneuver": "touchdown", "theta0": th, "optimal": True,
                                     "policy": [0.5, 0.5], "outcome": tr.outcome,
                                     "t_final": tr.t_final,
                                     "mode_sequence": [int(m) for m in tr.mode_sequence],
                                     "event_times": list(tr.event_times)},
                    offset + int(tr.t_final * NS))
            offset += int((tr.t_final + 0.5) * NS)
    return {"points": num, "state_messages": states, "rate_hz": 200,
            "file_MB": buf.tell() / 1e6}


def main() -> None:
    tr = simulate("touchdown", 0.05, (2.0, 0.5), sample_dt=0.005)
    result = {
        "trajectory_samples": int(tr.samples.shape[0]),
        "write_states": _states_rate(tr.samples, repeats=max(1, 200_000 // tr.samples.shape[0])),
        "write_per_message": _per_message_rate(tr.samples, 20_000),
        "sweep_201_at_200Hz": _sweep_size(),
    }
    result["acceptance"] = {
        "write_states_ge_100k_msg_per_s": result["write_states"]["msg_per_s"] >= 1e5,
        "sweep_file_lt_10MB": result["sweep_201_at_200Hz"]["file_MB"] < 10.0,
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

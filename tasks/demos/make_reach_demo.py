#!/usr/bin/env python3
"""Build ``reach_demo.npz``: the demonstration the scenarios' DMPs learn from.

The paper learns its DMP from one demonstration of the right hand, from (0.095, -0.466,
0.404) m to (1.701, -0.586, 0.761) m (Sec. 5.1), whose shape it does not give. Here the
shape comes from a real human reach: the wrist path of participant ADL001's first forward
reach with the right arm (``data/human_reaching``, MIT licence). The motion is trimmed to
where the wrist moves faster than 5 % of its peak speed. It is then mapped onto the paper's
start and goal by a similarity of the chord frame (``wholebody.planning.align_to_chord``):
the along-chord progress and the lateral and vertical deviations from the chord are kept,
scaled by the ratio of chord lengths. The
timing is stretched to the 5 s the paper's reaches take. The file holds ``times`` (s),
``positions`` (m, world) and ``source`` (text).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wholebody.planning.demonstration import align_to_chord

HERE = Path(__file__).resolve().parent
RECORDING = HERE.parents[1] / "data" / "human_reaching" / "joint_centres" / "ADL001_forward_R1.csv"
START = np.array([0.095, -0.466, 0.404])
GOAL = np.array([1.701, -0.586, 0.761])
DURATION = 5.0


def main() -> None:
    data = np.genfromtxt(RECORDING, delimiter=",", names=True)
    t = data["time_s"]
    wrist = np.column_stack([data["wrist_x"], data["wrist_y"], data["wrist_z"]]) / 1000.0
    speed = np.linalg.norm(np.gradient(wrist, t, axis=0), axis=1)
    moving = np.flatnonzero(speed > 0.05 * speed.max())
    k0, k1 = moving[0], moving[-1] + 1
    t, wrist = t[k0:k1] - t[k0], wrist[k0:k1]
    positions = align_to_chord(wrist, START, GOAL)
    times = t * DURATION / t[-1]
    source = (
        f"wrist path of {RECORDING.name} (UE_ADLdatabase, MIT), frames {k0}-{k1 - 1}, "
        f"mapped onto {START.tolist()} -> {GOAL.tolist()} m over {DURATION} s"
    )
    np.savez(HERE / "reach_demo.npz", times=times, positions=positions, source=np.array(source))
    print(f"wrote {HERE / 'reach_demo.npz'}: {len(times)} samples; {source}")


if __name__ == "__main__":
    main()

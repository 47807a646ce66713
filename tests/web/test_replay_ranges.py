"""``omnical monitor BAG`` on a real recording of raw distances only (CUHK-SZ UWB, no vendor
positions): the replay multilaterates them, so the page shows the tag move, and says so."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omnical.bags.bag import write_bag
from omnical.recording.topics import BEACON_RAW_DISTANCE, HEDGE_POS_ANG
from omnical.web.replay import load_replay
from sibling import sibling_module

uwb = sibling_module("ips/uwb_bags.py")


def test_a_raw_range_recording_replays_with_omnicals_fixes(tmp_path: Path) -> None:
    run = uwb.cuhksz_run(0)
    assert run.recording.has(BEACON_RAW_DISTANCE) and not run.recording.has(HEDGE_POS_ANG)
    payload = load_replay(write_bag(run.recording, tmp_path / "uwb.mcap"))
    fix = payload["streams"]["fix"]
    t = np.asarray(fix["t"])
    usable = (np.asarray(fix["flags"]) & 1) == 0
    assert len(t) > 100 and usable.mean() > 0.9, (len(t), usable.mean())
    assert payload["t1"] - payload["t0"] > 10.0  # the slider spans the run
    # the fixes follow the motion capture's truth (omnical locate: 0.057 m median on this run)
    xy = np.column_stack([fix["x"], fix["y"]])[usable]
    truth = uwb.truth_at(run, np.round(t[usable] * 1e9).astype(np.int64))
    err = np.hypot(*(xy - truth).T)
    print(f"{usable.sum()} of {len(t)} fixes usable, median error {np.median(err):.3f} m")
    assert np.median(err) < 0.1
    (note,) = [e["text"] for e in payload["events"] if "multilaterated by omnical" in e["text"]]
    assert note.startswith("no positions in the recording") and payload["note"] == note

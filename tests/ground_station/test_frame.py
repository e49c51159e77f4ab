"""ground_station.frame draws a recorded run's team at a moment: from the truth topics of a
log, the AMs where the log puts them; a log without them is refused, naming it."""
from __future__ import annotations

import pytest

from ground_station import frame
from ground_station.contract import OBJECT_STATE_TOPIC, ROS1, Out, truth_topic
from ground_station.mcap_io import McapLogWriter
from telemetry import binary
from telemetry.ros1 import VARIABLE


def _values(msg, **given):
    """Every field of `msg` zero (or empty), then `given`."""
    out = {}
    for f in msg.fields:
        if f.count is None:
            out[f.name] = "" if f.type == "string" else 0
        else:
            out[f.name] = [] if f.count == VARIABLE else [0] * f.count
    out.update(given)
    return out


def _log(path, with_truth=True):
    w = McapLogWriter(path)
    w.open()
    for k, t in enumerate((0.0, 1.0)):
        ns = int(t * 1e9)
        if with_truth:
            for s, x in ((4, -0.5), (5, 0.5)):
                v = _values(binary.AM_TRUTH, t=t, seq=k, sysid=s, p_WB=[x, 0.0, 1.0], q_WB=[1.0, 0, 0, 0],
                            p_WE=[x / 5, 0.0, 0.8], q_WE=[1.0, 0, 0, 0], p_W_joints=[x, 0, 0.95, x * 0.6, 0, 0.8])
                w.write(Out(truth_topic(s), binary.AM_TRUTH.name, ns, binary.AM_TRUTH.encode(v), ROS1))
        o = _values(binary.OBJECT, t=t, seq=k, p_WO=[0.0, 0.0, 0.6 + 0.3 * t], q_WO=[1.0, 0, 0, 0])
        w.write(Out(OBJECT_STATE_TOPIC, binary.OBJECT.name, ns, binary.OBJECT.encode(o), ROS1))
    w.close()
    return path


def test_the_frame_draws_every_am_of_the_log(tmp_path):
    out = frame.render(_log(tmp_path / "run.mcap"), 1.0, tmp_path / "team.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000


def test_a_log_without_truth_is_refused_with_exit_2(tmp_path, capsys):
    log = _log(tmp_path / "run.mcap", with_truth=False)
    assert frame.main([str(log), "--out", str(tmp_path / "x.png")]) == 2
    assert "no /sim/am/<sysid>/truth topic" in capsys.readouterr().err
    with pytest.raises(ValueError):
        frame.render(log, 0.0, tmp_path / "y.png")

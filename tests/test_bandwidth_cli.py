"""`uavtrack bandwidth`: the methods on a radio of limited capacity, with and without the
compact encoding and the event trigger, from the command line."""

import json

import numpy as np
import pandas as pd
import pytest

from uavtrack import cli
from uavtrack.experiments import bandwidth


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--set", "radio.bandwidth_bps=1000"], "radio.bandwidth_bps"),
        (["--set", "fusion.trigger=0.2"], "fusion.trigger"),
        (["--set", "comm_range=-3"], "comm_range"),
        (["--trials", "0"], "--trials"),
    ],
)
def test_bandwidth_refuses_bad_input_in_one_line_and_writes_nothing(tmp_path, args, named, capsys):
    out = tmp_path / "b"
    code = cli.main(["bandwidth", "--quick", *args, "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == 2 and named in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.slow  # 40 s of workers; the byte budget's own tests (test_wire) stay in the default
@pytest.mark.integration  # worker processes
def test_uavtrack_bandwidth_writes_its_tables_and_figure_and_resumes(tmp_path, capsys):
    from PIL import Image

    out = tmp_path / "b"
    args = ["bandwidth", "--quick", "--steps", "30", "--out", str(out), "--no-progress"]
    code = cli.main(args)
    _, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["methods"]) == list(bandwidth.METHODS)
    rows = pd.DataFrame(
        [
            {"method": m, "variant": v, "capacity": c, "rate": e["observation_rate"]["mean"],
             "bytes": e["bytes"]["mean"], "cost": e["cost"]["mean"]}
            for m, variants in summary["methods"].items()
            for v, row in variants.items()
            for c, e in row.items()
            if c != "keeps"
        ]
    )  # fmt: skip
    cells = sum(len(bandwidth.variants(m)) for m in bandwidth.METHODS)
    assert cells == 6 + 1 + 6 and len(rows) == cells * len(bandwidth.BANDWIDTHS)
    # paired against the method's unlimited paper run: its own cost is 0
    unlimited = rows[(rows.capacity == "unlimited") & (rows.variant == "paper")]
    assert (unlimited.cost == 0).all()
    reference = unlimited.set_index("method").rate
    assert ((reference[rows.method].to_numpy() - rows.rate) - rows.cost).abs().max() < 1e-12
    # 1 kbit/s carries nothing; more capacity never carries fewer bytes than 1 kbit/s
    starved = rows[rows.capacity == "1 kbit/s"]
    assert (starved.bytes == 0).all()
    assert (rows.bytes >= 0).all()
    # the compact encoding sends fewer bytes than the paper's exchange, unlimited
    free = rows[rows.capacity == "unlimited"].set_index(["method", "variant"]).bytes
    assert free["distributed", "compact"] < 0.6 * free["distributed", "paper"]
    # one frame to all sends less than a frame per receiver; the smallest, less than both
    for method in ("distributed", "greedy"):
        assert free[method, "broadcast"] < free[method, "paper"]
        assert free[method, "smallest"] < min(free[method, "both"], free[method, "broadcast"])
    assert len(summary["goals"]) == 8 and all(isinstance(g["met"], bool) for g in summary["goals"])
    assert all(
        np.isfinite(e["nees_inside"]["mean"])
        for e in summary["methods"]["distributed"]["smallest"].values()
        if isinstance(e, dict) and e["bytes"]["mean"] > 0
    )
    report = (out / "report.md").read_text()
    assert "## Goals" in report and "| both | 1 Mbit/s |" in report
    with Image.open(out / "bandwidth.png") as im:
        assert im.size[0] > 1000
    code = cli.main(args)  # resumes: every job is done
    out_text, _ = capsys.readouterr()
    assert code == 0 and "0 jobs run" in out_text

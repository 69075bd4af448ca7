"""labrig report on strain-command entries: the control metrics in --json and the HTML section.

The run uses the default simulated rig, whose truth is the dynamic model with the paper's
Table 1, and the compensation uses those same parameters: the compensated entry must then track
far better than the direct one (an independent check that the report reads the right samples
and that the metrics point the right way), and the --json keys are the issue's contract. The
compensated entry runs first: the controller assumes the actuator starts at rest, and after
another entry the stack's long memory (lam_t = 0.15) would still be creeping.
"""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from labrig.cli import app
from labrig.model import PAPER_TABLE1

runner = CliRunner()
KEYS = {"control", "frequency_hz", "tracking_nrmse_pct", "hysteresis_width_pct",
        "zero_command_strain_ue"}  # fmt: skip


def test_report_control_entries(tmp_path: Path) -> None:
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"params": PAPER_TABLE1.model_dump()}))
    proto = tmp_path / "ctl.yaml"
    proto.write_text(
        "name: control check\nrate_hz: 1000\nparams: params.json\nsteps:\n"
        "  - {kind: strain_sine, amplitude_ue: 800, frequency_hz: 10, cycles: 20, "
        "control: compensated}\n"
        "  - {kind: strain_sine, amplitude_ue: 800, frequency_hz: 10, cycles: 20, "
        "control: direct}\n"
    )
    run = tmp_path / "ctl.h5"
    res = runner.invoke(app, ["run", str(proto), "--out", str(run), "--seed", "3"])
    assert res.exit_code == 0, res.output
    html = tmp_path / "r.html"
    args = ["report", str(run), "--params", str(params), "--out", str(html), "--json"]
    # our model only: the peers are not what this checks (test_report_peers.py)
    res = runner.invoke(app, [*args, "--no-heldout", "--peers", "none"])
    assert res.exit_code == 0, res.output
    table = json.loads(res.stdout[res.stdout.index("{") :])
    d = table["strain_sine_800ue_10Hz_direct"]
    c = table["strain_sine_800ue_10Hz_compensated"]
    assert set(d) >= KEYS
    assert set(c) >= KEYS
    assert (d["control"], c["control"]) == ("direct", "compensated")
    assert d["frequency_hz"] == c["frequency_hz"] == 10
    # model = truth here: compensation removes most of the hysteresis and the tracking error
    assert c["hysteresis_width_pct"] < d["hysteresis_width_pct"] / 4
    assert c["tracking_nrmse_pct"] < d["tracking_nrmse_pct"] / 4
    assert abs(c["zero_command_strain_ue"]) < abs(d["zero_command_strain_ue"])
    page = html.read_text()
    section = page[page.index('id="control"') :]
    assert "strain_sine_800ue_10Hz_compensated" in section
    assert section.count("data:image/png;base64,") >= 1  # the Figs. 15-17 panel

"""The simulated whole-file SmartHysteresis stand-in (``labrig/studies/smart_standin.py``): the
authors' headerless CSV format, the file's time base and drive, the noise level, and that it
reads back through ``labrig import`` as PROVENANCE.md says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from labrig.studies.smart_standin import (
    NOISE_UM,
    drive_on_s,
    main,
    standin_rows,
    write_standin,
)


def test_rows_follow_the_file_time_base_drive_and_noise():
    """1 kHz for speed: 10 000 rows of k/rate s; 0 V before 7.3558 s (the drive formula's phase
    0), ``150 sin(2 pi t - 46.2178545458)`` after (checked against the formula itself); the
    displacements of two seeds differ by sqrt 2 NOISE_UM RMS within 5 % (noise only)."""
    rows = standin_rows(1, 1000.0)
    t, _s, v = rows.T
    assert rows.shape == (10_000, 3) and t[1] - t[0] == pytest.approx(1e-3)
    assert drive_on_s() == pytest.approx(7.3558, abs=1e-6)
    on = t >= drive_on_s()
    assert np.all(v[~on] == 0.0)
    np.testing.assert_allclose(
        v[on], 150.0 * np.sin(2 * math.pi * t[on] - 46.2178545458), atol=1e-9
    )
    a, b = standin_rows(1, 1000.0), standin_rows(2, 1000.0)
    # two seeds differ by noise only: RMS of the difference sqrt(2) NOISE_UM
    assert np.std(a[:, 1] - b[:, 1]) == pytest.approx(math.sqrt(2) * NOISE_UM, rel=0.05)
    # the idle start is the strain at rest (noise only), the drive moves it far beyond that
    assert np.std(a[~on, 1]) == pytest.approx(NOISE_UM, rel=0.1)
    assert np.ptp(a[on, 1]) > 50 * NOISE_UM


def test_written_as_the_authors_csv_and_never_overwritten(tmp_path, capsys):
    """Each row ``,time,displacement,voltage`` (no header); an existing file is refused (exit
    2, no traceback, the file untouched) unless ``--overwrite``."""
    path = write_standin(tmp_path / "s.csv", rate_hz=200.0)
    lines = path.read_text().splitlines()
    assert len(lines) == 2000 and lines[0].startswith(",0.00000000,")
    assert all(len(x.split(",")) == 4 and x.split(",")[0] == "" for x in lines[:50])
    data = np.loadtxt(path, delimiter=",", usecols=(1, 2, 3))
    np.testing.assert_allclose(data, standin_rows(1, 200.0), atol=1e-6)
    before = path.read_text()
    assert main([str(path), "--rate-hz", "200", "--seed", "2"]) == 2
    assert "exists" in capsys.readouterr().err and path.read_text() == before
    assert main([str(path), "--rate-hz", "200", "--seed", "2", "--overwrite"]) == 0
    assert path.read_text() != before


@pytest.mark.parametrize(("rate", "ok"), [("9.99", False), ("10", True), ("0.05", False)])
def test_a_rate_that_cannot_sample_the_drive_is_refused(tmp_path, rate: str, ok: bool):
    """Below 10 Hz the 1 Hz drive is not sampled (0.05 Hz wrote an empty file and exited 0):
    exit 2 naming the option, nothing written; 10 Hz is accepted."""
    out = tmp_path / "s.csv"
    if ok:
        assert main([str(out), "--rate-hz", rate]) == 0 and out.stat().st_size > 0
        return
    with pytest.raises(SystemExit) as e:
        main([str(out), "--rate-hz", rate])
    assert e.value.code == 2 and not out.exists()

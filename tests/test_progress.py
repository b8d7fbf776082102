"""charctl.progress: the plain line's ETA (a non-terminal: nohup, CI, pipes)."""

import pytest

from charctl.progress import TrainingProgress, eta_text


@pytest.mark.parametrize(
    ("remaining", "rate", "text"),
    [
        (3_600_000.0, 500.0, "ETA 2h 00m"),  # 7,200 s
        (7_500.0, 1.0, "ETA 2h 05m"),
        (250.0, 1.0, "ETA 4m 10s"),
        (9.0, 1.0, "ETA 9s"),
        (0.0, 10.0, "ETA 0s"),
        (-5.0, 10.0, "ETA 0s"),  # past the total (the last iteration overshoots)
        (100.0, 0.0, "ETA ?"),
    ],
)
def test_eta_text_by_hand(remaining, rate, text):
    assert eta_text(remaining, rate) == text


def test_the_plain_line_shows_the_rate_and_the_eta(capsys, monkeypatch):
    """On a non-terminal, half of 1,000 samples done in 10 s: 50 samples/s, 500 left, 10 s to go."""
    now = [100.0]
    monkeypatch.setattr("charctl.progress.time.perf_counter", lambda: now[0])
    monkeypatch.setattr("sys.stderr.isatty", lambda: False)
    bar = TrainingProgress(1000, "run", plain_every=5.0)
    now[0] = 110.0
    bar.update(500, r_S=0.5)  # more than plain_every since the last line (none yet): printed
    assert capsys.readouterr().err.strip() == "run: 500/1,000 samples (50%), 50 samples/s, ETA 10s  r_S=0.5"

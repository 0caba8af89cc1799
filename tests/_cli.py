"""The check every test of a refused command makes: exit status 2 and one line."""

from __future__ import annotations

from diffcontrol.cli import main


def one_line(capsys, argv, *needles, absent=()) -> str:
    """``main(argv)`` exits 2 with one line holding every needle (and none of ``absent``), no
    traceback; returns the line."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    for needle in absent:
        assert needle not in err, err
    return err

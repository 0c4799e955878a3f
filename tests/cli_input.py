"""Running ``reach`` on bad input in the tests: exit 2 and one line, never a traceback."""

from reach.cli import main


def bad_input(argv: list[str], capsys) -> str:
    """Run ``reach ARGV``: it must exit 2 with one line on stderr, which is returned."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err.strip()

"""Back-end options: names and types checked, one clear line per problem."""

from __future__ import annotations

import pytest
from hypothesis import given, strategies as st

from reach.backends.montecarlo import Options as MonteCarloOptions
from reach.backends.star import StarOptions
from reach.backends.taylor import Options as TaylorOptions
from reach.cli import main
from reach.errors import InputError


def test_numbers_are_coerced_to_the_field_type():
    opts = TaylorOptions.from_dict({"e_tol": 1, "max_splits": 3.0, "integration_tol": 1e-8})
    assert opts.e_tol == 1.0 and isinstance(opts.e_tol, float)
    assert opts.max_splits == 3 and isinstance(opts.max_splits, int)
    assert StarOptions.from_dict({"step": None}).step is None


@pytest.mark.parametrize("options, field", [
    ({"e_tol": "abc"}, "options.taylor.e_tol"),
    ({"max_splits": 1.5}, "options.taylor.max_splits"),
    ({"max_splits": True}, "options.taylor.max_splits"),
    ({"remainder": "exact"}, "options.taylor.remainder"),
    ({"step_tol": 1000}, "options.taylor.step_tol"),
    ({"step_tol": 0}, "options.taylor.step_tol"),
    ({"bogus": 1}, "options.taylor.bogus"),
])
def test_bad_taylor_options_name_the_field(options, field):
    with pytest.raises(InputError) as err:
        TaylorOptions.from_dict(options)
    assert err.value.field == field


@given(st.one_of(st.text(max_size=5), st.booleans(), st.floats(allow_nan=False).filter(lambda v: not v.is_integer()),
                 st.lists(st.integers(), max_size=2)))
def test_integer_fields_take_integers_only(value):
    with pytest.raises(InputError):
        MonteCarloOptions.from_dict({"samples": value})


def test_cli_reads_exponents_without_a_dot(capsys):
    # YAML 1.1 reads 1e-4 as text; the command line takes it as the number
    args = ["check", "SRA01", "properties/rendezvous.yaml", "-b", "star", "-p", "thrust", "--counterexamples",
            "/nonexistent", "-o", "touch_tolerance=1e-6"]
    assert main(args) == 0
    assert "thrust" in capsys.readouterr().out
    assert main(args + ["-o", "bogus=2"]) == 2
    assert capsys.readouterr().err.strip() == ("reach: options.star.bogus: unknown star option; known: "
                                               + ", ".join(sorted(StarOptions.__dataclass_fields__)))


@pytest.mark.parametrize("name", ["input_cells", "rebase_cells", "linearise_inflations", "max_lps", "max_stars"])
def test_a_count_past_any_meaning_is_refused_at_its_option(name):
    """``-o input_cells=1e308`` reached the exploration as a 309-digit integer (UNKNOWN, "Python
    int too large to convert to C long"): a count without its own bound is at most 1e9."""
    with pytest.raises(InputError) as err:
        StarOptions.from_dict({name: 1e308})
    assert err.value.field == f"options.star.{name}" and "at most 1e+09" in str(err.value)
    assert getattr(StarOptions.from_dict({name: 10 ** 9}), name) == 10 ** 9

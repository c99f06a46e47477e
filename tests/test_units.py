"""Datasheet-unit formatting of the report tables."""


def test_an_interval_is_printed_with_the_digits_that_tell_its_ends_apart():
    from companion.units import fmt_interval

    assert fmt_interval(1.0312, 1.0280, 1.0333) == "1.031 [1.028, 1.033]"  # "1.03 [1.03, 1.03]" before
    assert fmt_interval(33.8, 23.5, 40.9) == "33.8 [23.5, 40.9]"  # 3 digits where they do
    assert fmt_interval(1.39, 1.381, 1.389) == "1.39 [1.38, 1.39]"
    assert fmt_interval(2e-4, 1e-4, 3e-4) == "2.00e-04 [1.00e-04, 3.00e-04]"
    assert fmt_interval(5.0, 5.0, 5.0) == "5 [5, 5]"  # a degenerate interval stays as it is
    assert fmt_interval(1.0, 0.9999995, 1.0000005).count("[1, 1]") == 1  # at most 6 digits

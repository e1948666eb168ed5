"""``koopguide bench guidance`` refuses bad query settings with one line naming the value (before any work)."""

from __future__ import annotations

import pytest

from koopguide.harness import guidance_bench


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["--query-sizes", "300"], "'300'"),
        (["--query-sizes", "200,x"], "'200,x'"),
        (["--query-hz", "-1"], "got -1"),
        (["--query-hz", "50"], "got 50"),
    ],
)
def test_bad_query_settings_exit_2_naming_the_value(argv, named, capsys):
    with pytest.raises(SystemExit) as exit_info:
        guidance_bench.main(argv)
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert exit_info.value.code == 2 and named in err and "query" in err, err

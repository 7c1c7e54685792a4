"""Sweep runs are area function calls: :class:`simfab.sweep.runs.ApiCall` in the task, built from
the spec's command line by the CLI."""

import pickle

from simfab.sweep.runs import META_COLUMNS, ApiCall, execute_run


def test_a_run_calls_the_area_function_and_picks_its_figures(tmp_path):
    call = ApiCall(command="crowd simulate", kwargs=dict(scale=(1, 10), tasks=3, practitioners=4, seed=1))
    call = pickle.loads(pickle.dumps(call))  # it travels to a Dask worker
    got = execute_run(call=call, figures=[("raters", "raters"), ("first", "tasks.0"), ("csv", "outputs.ratings_csv")],
                      run_dir=str(tmp_path / "run"), keep=True, scene=None)
    assert got["raters"] == 4 and got["first"] == "q1"
    assert got["csv"].startswith(str(tmp_path / "run"))  # the run wrote into its own folder


def test_command_lines_become_api_calls_where_the_area_has_one():
    from simfab.cli.sweep_runner import ArgvCall, command_call

    c = command_call(["couple", "simulate", "{scene}", "--steps", "6", "--friction", "0.3", "--seed", "0"])
    assert isinstance(c, ApiCall) and c.command == "couple simulate" and c.args == ("{scene}",)
    assert c.kwargs["simulation"] == {"steps": 6, "h_in": None} and c.kwargs["contact"]["friction"].value == 0.3
    assert c.kwargs["contact"]["friction"].source == "--friction"  # a bad value is blamed on the spec's flag
    bad = command_call(["couple", "simulate", "{scene}", "--steps", "0"])  # reported by the run (bad_input row)
    assert isinstance(bad, ArgvCall)


def test_the_table_columns_are_the_specs():
    from simfab.cli.sweep_spec import META_COLUMNS as spec_columns

    assert META_COLUMNS == spec_columns

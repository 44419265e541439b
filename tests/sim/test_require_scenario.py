"""The simulator's one check of a scenario name, as the library and the CLI (sim, hil, demo) use it."""

from __future__ import annotations

import pytest

from accelnav.errors import UserError
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.sim.trajectories import ALL_SCENARIOS, require_scenario


def test_a_known_scenario_passes():
    for name in ALL_SCENARIOS:
        require_scenario(name)


def test_an_unknown_one_is_refused_in_one_line_in_the_callers_terms():
    with pytest.raises(ValueError, match=r"^scenario: unknown scenario 'moon'; accepted: 'stationary'"):
        require_scenario("moon")
    with pytest.raises(UserError, match=r"^--scenario: unknown scenario 'moon'") as err:
        require_scenario("moon", "--scenario", UserError)
    assert "\n" not in str(err.value)


def test_simulate_refuses_through_it(default_model):
    with pytest.raises(ValueError, match=r"^scenario: unknown scenario 'moon'"):
        simulate(default_model, "moon", 1.0, 1)

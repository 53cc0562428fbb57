"""The farm session under the simulator node (crop_sim_ros.session): commands, steps and resets as plain Python,
without ROS or processes (the node's behaviour over ROS is tested in test_ros_sim*.py)."""

from __future__ import annotations

import math
from datetime import date, datetime, time, timedelta, timezone

import numpy as np
import pytest

from crop_sim_ros.session import FREE_RUNNING_STEP_REFUSAL, Command, FarmSession, farm_time_ns
from crop_sim_ros.task import IrrigationEnv


def started(scenario: str = "benton-generated", seed: int = 3) -> FarmSession:
    session = FarmSession(IrrigationEnv(scenario))
    session.reset(session.env, seed, None)
    return session


def test_before_the_first_reset_every_command_and_step_is_refused():
    session = FarmSession(IrrigationEnv("benton-generated"))
    outcome = session.command(Command(0, 5.0))
    assert not outcome.accepted and outcome.timing and "no season yet" in outcome.text
    step = session.step()
    assert not step.ok and not step.environment_failed and "call ~/reset" in step.error
    assert (session.episode, session.commands_received, session.commands_rejected) == (0, 1, 1)


@pytest.mark.parametrize("command, why, timing", [
    (Command(0, 1.0, 7), "episode 7 is not the current episode 1", True),
    (Command(1, 1.0), "day 1 is in the future: the current day is 0", True),
    (Command(0, 1.0, field="field3"), "frame_id 'field3' is not this simulator's field 'farm'", False),
    (Command(0, 1.0, stamp_ns=farm_time_ns(date(2000, 4, 10), 0)),
     "header.stamp 955324800.000000000 s is not the farm time of day 0 (", False),
    (Command(0, 1.0, stamp_ns=1), "header.stamp 0.000000001 s is not the farm time of day 0", False),
    (Command(0, math.nan), "irrigation nan mm is not a finite number", False),
    (Command(0, math.inf), "irrigation inf mm is not a finite number", False),
    (Command(0, -0.5), "irrigation -0.5 mm is negative", False),
    (Command(0, 100.5), "exceeds the limit of 100 mm/day", False),
])
def test_a_bad_command_is_refused_with_its_reason_and_nothing_is_pending(command, why, timing):
    session = started()
    outcome = session.command(command)
    assert not outcome.accepted and why in outcome.text and outcome.timing == timing
    assert outcome.command is command and outcome.current_day == 0
    assert session.pending is None and session.commands_rejected == 1 and session.commands_accepted == 0


def test_a_command_stamped_with_its_day_and_addressed_to_the_field_or_to_any_is_accepted():
    """The farm time of a day is midnight UTC of the sowing date plus the day; '' and 0 leave field and stamp
    unchecked; ANY_EPISODE is valid in the current episode."""
    session = FarmSession(IrrigationEnv("benton-generated"), field="field7")
    session.reset(session.env, 3, None)
    session.step()
    today = farm_time_ns(session.sowing, 1)
    assert today == int(datetime.combine(session.sowing + timedelta(days=1), time(), timezone.utc).timestamp()) * 10**9
    for command in (Command(1, 2.0, 1, today, "field7"), Command(1, 3.0), Command(1, 4.0, -1, 0, "field7")):
        outcome = session.command(command)
        assert outcome.accepted and session.pending == (command, outcome.sequence), outcome.text
    assert session.step().applied_mm == 4.0


def test_the_last_accepted_command_of_the_day_is_applied_once_and_a_day_without_one_gets_0_mm():
    session, reference = started(), IrrigationEnv("benton-generated")
    reference.reset(seed=3)
    assert session.command(Command(0, 4.0)).accepted and session.command(Command(0, 6.0, 1)).accepted
    step = session.step()
    _, reward, *_ = reference.step(6.0)
    assert step.ok and (step.day_before, step.day, step.applied_mm, step.sequence) == (0, 1, 6.0, 2)
    assert step.reward == reward and session.pending is None and session.days_without_command == 0
    past = session.command(Command(0, 3.0))
    assert not past.accepted and "day 0 is past" in past.text and past.timing
    step = session.step()  # no command for day 1
    assert (step.applied_mm, step.sequence, session.days_without_command) == (0.0, -1, 1)
    assert (session.commands_received, session.commands_accepted, session.commands_rejected) == (3, 2, 1)


def test_a_stepping_command_is_refused_unless_lockstep():
    session = started()
    outcome = session.command(Command(0, 2.0), and_step=True, lockstep=False)
    assert not outcome.accepted and FREE_RUNNING_STEP_REFUSAL in outcome.text and session.pending is None
    assert session.command(Command(0, 2.0), and_step=True).text.endswith(", stepping")


def test_a_season_ends_once_and_the_session_refuses_steps_and_commands_until_the_next_reset():
    session = started()
    total = 0.0
    while not session.ended:
        session.command(Command(session.day, 8.0))
        step = session.step()
        total += step.reward
    assert step.terminated and step.yield_t_ha > 5 and session.end_reason == f"crop mature on day {session.day}"
    assert session.episode_return == pytest.approx(total, rel=1e-12)
    after = session.step()
    assert not after.ok and "the season has ended (crop mature" in after.error and after.day == session.day
    assert not session.command(Command(session.day, 1.0)).accepted
    info = session.reset(session.env, 4, 0)
    assert (session.episode, session.day, session.ended, session.episode_return) == (2, 0, False, 0.0)
    assert session.weather_season == info["season"] == 0 and session.seed == 4 and session.days_without_command == 0


def test_a_failing_environment_or_reset_leaves_the_season_as_it_was():
    session = started()
    session.step()
    before = (session.episode, session.day, session.obs.copy(), session.episode_return, session.sowing)

    class Broken:
        scenario = session.env.scenario

        def step(self, mm):
            raise RuntimeError("the model refused")

        def reset(self, seed=None, options=None):
            raise ValueError("weather file unreadable")

    good = session.env
    with pytest.raises(ValueError, match="weather file unreadable"):
        session.reset(Broken(), 1, None)
    assert session.env is good
    session.env = Broken()
    step = session.step()
    assert not step.ok and step.environment_failed and "RuntimeError: the model refused" in step.error
    after = (session.episode, session.day, session.obs, session.episode_return, session.sowing)
    assert after[:2] == before[:2] and np.array_equal(after[2], before[2]) and after[3:] == before[3:]


def test_a_command_cut_by_the_capacity_or_the_quota_is_reported_with_its_cause():
    session = started("benton-capacity", seed=0)
    session.command(Command(0, 20.0))
    step = session.step()
    assert step.cut and (step.requested_mm, step.applied_mm) == (20.0, 4.5)
    assert session.cut_reason(step) == ("cut: 4.5 of the 20 mm commanded for day 0 applied, by the irrigation "
                                        "capacity of 4.5 mm/d")
    quota = started("benton-quota", seed=0)
    quota_mm = quota.terms[3]
    while not quota.ended:
        quota.command(Command(quota.day, 8.0))
        step = quota.step()
        if step.cut and step.applied_mm < 8.0:
            break
    assert step.cut and f"by the season's quota of {quota_mm:g} mm ({step.applied_mm:g} mm were left)" in \
        quota.cut_reason(step)


def test_the_season_terms_of_a_paper_and_a_family_task():
    paper = started()
    assert math.isnan(paper.terms[0]) and paper.terms[3] == math.inf and paper.terms[4] == 100.0
    family = started("benton-quota", seed=0)
    price, water_cost, event_cost, quota, capacity = family.terms
    assert 150 <= price <= 300 and water_cost > 0 and 150 <= quota <= 450 and capacity == 8.0

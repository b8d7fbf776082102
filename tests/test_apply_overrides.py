"""`charctl.config.apply_overrides`: a resume's overrides parse as a fresh `charctl train`'s (Hydra's grammar)."""

import pytest
from omegaconf import OmegaConf

from charctl.config import apply_overrides
from charctl.errors import CharctlError


def _recorded():
    return OmegaConf.create(
        {
            "reward": {"w_track": 1.0, "w_track_skills": {"spindance": 4.0, "breakdance": 4.0}},
            "use_skills": ["walk"],
            "seed": 1,
        }
    )


def test_hydra_values_parse_as_on_a_fresh_train():
    """The compact dict syntax Hydra accepts (`{a:1}`, no space after the colon) is a mapping merged into the
    recorded one, a list replaces a list, a number stays a number, `~key` removes the key."""
    cfg = apply_overrides(
        _recorded(),
        ["reward.w_track_skills={breakdance:8.0,left_kick:2}", "use_skills=[walk,run]", "seed=3", "~reward.w_track"],
    )
    assert OmegaConf.to_container(cfg.reward.w_track_skills) == {"spindance": 4.0, "breakdance": 8.0, "left_kick": 2}
    assert list(cfg.use_skills) == ["walk", "run"] and cfg.seed == 3
    assert "w_track" not in cfg.reward


def test_the_recorded_config_is_left_as_it_was():
    recorded = _recorded()
    apply_overrides(recorded, ["seed=7", "reward.w_track_skills={jump:2.0}"])
    assert recorded.seed == 1 and "jump" not in recorded.reward.w_track_skills


@pytest.mark.parametrize("bad", ["seed", "reward.w_track_skills={a:"])
def test_bad_overrides_are_one_line_errors(bad):
    with pytest.raises(CharctlError) as err:
        apply_overrides(_recorded(), [bad])
    assert "\n" not in str(err.value)

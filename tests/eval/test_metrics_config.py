"""MetricConfig options."""

import pytest

from slime_match.errors import ConfigError
from slime_match.eval.metrics.config import MetricConfig


def test_config_rejects_unknown_options():
    assert MetricConfig.from_options(t_perp=10).t_perp == 10
    with pytest.raises(ConfigError):
        MetricConfig.from_options(t_prep=10)

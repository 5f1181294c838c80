"""Non-learned grasp planners served beside VGN through the same API."""

from service.baseline.antipodal import AntipodalConfig, plan_antipodal

__all__ = ["AntipodalConfig", "plan_antipodal"]

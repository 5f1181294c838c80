"""Non-learned grasp planners served beside VGN through the same API."""

from service.baseline.antipodal import AntipodalConfig, grips_antipodally, plan_antipodal

__all__ = ["AntipodalConfig", "grips_antipodally", "plan_antipodal"]

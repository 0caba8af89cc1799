"""The trebuchet of the 2019 post, a built-in system in its own folder, as a user's task is:
its dynamics (``system``), its task (``task``: aim at a target in a wind), and what the layers
do with it their own way (``hooks``: its runs judged by the miss over random targets and drawn
as a throw, its data as recorded throws, its physics fitted to measured distances, its RL
baselines), imported when a layer's hook first meets the task (the registry names it)."""

from .system import TrebuchetParams
from .task import TrebuchetAiming

__all__ = ["TrebuchetAiming", "TrebuchetParams"]

"""The trebuchet beyond its task (``task``): its runs judged by the miss over
random targets and drawn as a throw (``runs``), its data as recorded throws (``throws``,
``record``) and its physics fitted to measured distances (``fit``), registered with the
layers' hooks (``tasks._hooks``)."""

from ...compare.baselines import rl_setup
from ...identify._routes import model_route
from ...identify.recording import record_task
from . import runs  # noqa: F401  (registers evaluate_run, write_figures, animate_run)
from .compare import RL
from .fit import THROWS
from .record import record_data
from .task import TrebuchetAiming

record_task.register(TrebuchetAiming)(record_data)
rl_setup.register(TrebuchetAiming)(lambda task: RL)


@model_route.register(TrebuchetAiming)
def _route(task: TrebuchetAiming) -> object:
    """The grey box fitted to the measured distances (``fit.THROWS``)."""
    return THROWS

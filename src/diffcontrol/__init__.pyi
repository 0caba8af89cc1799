# The public names of `diffcontrol`, for type checkers and editors: the package imports them
# when first used (PEP 562, __init__.py), so that `import diffcontrol` does not import JAX.
from .checks import check_task as check_task
from .config import ODETrainConfig as ODETrainConfig
from .config import TrainConfig as TrainConfig
from .controllers import MLPController as MLPController
from .deploy import export as export
from .errors import ConfigError as ConfigError
from .errors import DiffcontrolError as DiffcontrolError
from .evaluation import evaluate as evaluate
from .identify import fit as fit
from .identify import record as record
from .runs import Run as Run
from .runs import load as load
from .runs import open_run as open_run
from .tasks import ContinuousTask as ContinuousTask
from .tasks import Task as Task
from .tasks import register as register
from .training import TrainResult as TrainResult
from .training import sweep as sweep
from .training import train as train

__version__: str
__all__: list[str]

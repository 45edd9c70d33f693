"""In-silico training (eq. projected-sgd, the paper's mini-batch practice, optax) and the weight cache."""

from ._cache import cache_dir as cache_dir
from ._cache import default_config as default_config
from ._cache import evaluate as evaluate
from ._cache import load_or_train as load_or_train
from ._cache import load_weights as load_weights
from ._cache import save_weights as save_weights
from ._sgd import METHODS as METHODS
from ._sgd import Pinned as Pinned
from ._sgd import pin as pin
from ._sgd import TrainConfig as TrainConfig
from ._sgd import empirical_sampler as empirical_sampler
from ._sgd import minibatch_sgd as minibatch_sgd
from ._sgd import projected_sgd as projected_sgd
from ._sgd import robbins_monro as robbins_monro
from ._sgd import sample_loss as sample_loss
from ._sgd import stderr_progress as stderr_progress
from ._sgd import train as train
from ._sgd import train_with_history as train_with_history

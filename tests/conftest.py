"""Shared test configuration: single-threaded torch so that the tests stay fast beside other jobs."""
import torch

torch.set_num_threads(1)

"""Neural surrogate: the multi-resolution enhanced U-Net and its building blocks, and an FNO alternative."""
from .blocks import EdgeAwareConv, EnhancedDoubleConv, MultiResolutionLift, SpatialAttention
from .fno import FNONet, fno_available
from .model import BOUNDARIES, MultiResUNet, apply_displacement, boundary_mask
from .registry import ARCHS, build_model, from_tensor_state, tensor_state

__all__ = ["MultiResUNet", "FNONet", "fno_available", "EdgeAwareConv", "EnhancedDoubleConv", "MultiResolutionLift",
           "SpatialAttention", "boundary_mask", "apply_displacement", "BOUNDARIES", "ARCHS", "build_model",
           "tensor_state", "from_tensor_state"]

"""Neural surrogate: the multi-resolution enhanced U-Net and its building blocks."""
from .blocks import EdgeAwareConv, EnhancedDoubleConv, MultiResolutionLift, SpatialAttention
from .model import BOUNDARIES, MultiResUNet, apply_displacement, boundary_mask

__all__ = ["MultiResUNet", "EdgeAwareConv", "EnhancedDoubleConv", "MultiResolutionLift", "SpatialAttention",
           "boundary_mask", "apply_displacement", "BOUNDARIES"]

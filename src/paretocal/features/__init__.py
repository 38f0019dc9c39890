"""Feature extraction: image edges and distance transforms, LiDAR rings and edge points."""

from .image import ImageFeatures, distance_transform, edge_map, image_features
from .lidar import DEPTH_EDGE, GROUP_NAMES, INTENSITY_EDGE, SMOOTH, LidarFeatures, lidar_features
from .prepare import FrameFeatures, prepare_frame, stratified_order

__all__ = ["DEPTH_EDGE", "GROUP_NAMES", "INTENSITY_EDGE", "SMOOTH", "FrameFeatures",
           "ImageFeatures", "LidarFeatures", "distance_transform", "edge_map", "image_features",
           "lidar_features", "prepare_frame", "stratified_order"]

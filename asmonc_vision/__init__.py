"""asmonc_vision: a wearable stereo-vision obstacle detector (Molton et al. 1998), on ROS 2."""
__version__ = '0.1.0'

"""kinfu: offline robot spatial attention and next-best-view planning on recorded RGB-D data."""

__version__ = "0.1.0"

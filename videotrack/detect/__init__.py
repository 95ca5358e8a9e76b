"""Marker detection: video input (backends), views and de-interlacing, the filter chain,
marker regions and colours, the detection of a video, detections files and their edits."""

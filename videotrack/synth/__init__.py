"""Synthetic data with known truth: scenes, rendered videos, smooth random motion, the
paper's set-up, synthetic projects and keypoint sessions."""

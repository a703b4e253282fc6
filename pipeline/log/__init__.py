"""Recordings: one ROS 2 compatible rosbag2 directory (metadata.yaml + MCAP) per episode."""

from __future__ import annotations

from pipeline.log.bag import BagSummary, write_episode_bag

__all__ = ["BagSummary", "write_episode_bag"]

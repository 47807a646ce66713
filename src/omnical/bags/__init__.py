"""Bag files: recordings as ROS bags (ROS 2 MCAP, ROS 1), exported as CSV and TUM.

``read_bag``/``write_bag`` for whole recordings, :class:`BagRecorder` for runs that flush as
they go, ``recover_bag`` for a run cut short, ``summarize_bag`` for counts from the index.
"""

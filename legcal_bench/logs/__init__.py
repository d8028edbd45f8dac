"""Robot logs in: ROS 2 / ROS 1 bags and CSV/Parquet tables read through a mapping file,
aligned onto one clock, static double support found, recordings out (`import_log`)."""

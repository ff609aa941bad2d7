"""Curated teacher demonstrations as LeRobotDataset episodes (paper Sec. III-C)."""

"""Curated teacher demonstrations as LeRobotDataset episodes (paper Sec. III-C), DAgger relabelling, and the
repair of a crashed dataset. `collect_cli` is the command line; `collection_loop` rolls out, curates and writes."""

"""The main job (`run`, behind `blindgrasp-pipeline`), the commands it runs (`recipe`), its report (`job_report`),
and the glove student (`glove_train`)."""

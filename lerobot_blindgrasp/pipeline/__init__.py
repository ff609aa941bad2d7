"""The main job (`run`, behind `blindgrasp-pipeline`), the commands it runs (`recipe`), its report with the grasp
strips (`job_report`), and the glove student (`glove_train`)."""

"""The main job: from a teacher to an evaluated student (`run`, the stage runner behind `blindgrasp-pipeline`), the
student recipe it follows (`recipe`), and the report it writes (`report`, with its grasp strips, `grasp_strips`)."""

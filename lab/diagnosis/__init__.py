"""Research diagnosis, each a `python -m lab.diagnosis.<tool>` command: a teacher's fingertip contacts (`contacts`),
how varied a demo set is (`diversity`), a teacher run's training progress (`progress`), why a student trails its
teacher (`student_diagnosis`, with the fit measures in `student_fit`), and how often the side-grasp script that the
shipped teacher's recipe clones lifts each object (`script_success`)."""

"""Reading what training and evaluation produced: success rates with Wilson intervals (`rates`), paired comparison
of two evaluations (`compare`), Table V (`table_v`), plots (`plots`), a teacher run's training progress
(`progress`), fingertip contacts (`contacts`), demo diversity (`diversity`) and the student's failure diagnosis
(`student_diagnosis`). The robot and the policy never import these."""

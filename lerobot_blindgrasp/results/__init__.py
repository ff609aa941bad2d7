"""What every recorded number is made of: success rates with their 95 % Wilson intervals (`rates`), the paired
comparison of two evaluations on the same start states (`compare`) and the plots (`plots`).

Teacher evaluation, the pipeline's report, the analysis tools and the robustness sweep all read these; this package
imports nothing above the object catalogue, and never MuJoCo."""

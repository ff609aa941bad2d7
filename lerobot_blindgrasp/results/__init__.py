"""What every recorded number is made of: success rates with their 95 % Wilson intervals (`rates`), the paired
comparison of two evaluations on the same start states (`compare`) and the plots (`plots`). Never imports MuJoCo."""

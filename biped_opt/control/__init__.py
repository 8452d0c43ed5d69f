"""Optimal control of any system: problems (:mod:`~biped_opt.control.problems`), the optimal
policy and value (:mod:`~biped_opt.control.solve`), outcome derivatives by the variational
equation and saltation matrices (:mod:`~biped_opt.control.derivatives`) and the one-sided
derivatives of the optimal value and policy of Theorem 1 (:mod:`~biped_opt.control.theorem1`)."""

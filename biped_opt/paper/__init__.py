"""The paper's presets over the one lane: what is Banjanin & Burden's own [1]_ rather than any
system's: the biped's problems under their paper names (:mod:`~biped_opt.paper.problems`), their
optimal policies and values in the paper's words (:mod:`~biped_opt.paper.solve`), its one-sided
derivatives over (th0, u1, u2, u12) (:mod:`~biped_opt.paper.derivatives`), its sweep tables
(:mod:`~biped_opt.paper.sweeps`) and nonsmooth tables (:mod:`~biped_opt.paper.nonsmooth`), and
the data of Figs. 2-4 and of the control experiment (:mod:`~biped_opt.paper.figures`); MODEL.md
specifies them. Each runs on the one lane (:mod:`biped_opt.control`, :mod:`biped_opt.analysis`).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

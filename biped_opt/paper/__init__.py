"""The paper's presets over the one lane: its problems, names and tables ([1]_, MODEL.md).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

"""The paper's presets over the one lane: what is Banjanin & Burden's own (the biped's maneuvers,
fixed inputs and problems, the data of Figs. 2-4 and of the control experiment) rather than any
system's."""

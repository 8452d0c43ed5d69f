"""System files written as a user writes them from the manual's "Your own system" tutorial
(docs/tutorials/own_system.md), and
independent references for them that import nothing from biped_opt (closed-form flights with
certified event isolation, SciPy solve_ivp with events): tests/simulation/test_user_suite.py
compares the two."""

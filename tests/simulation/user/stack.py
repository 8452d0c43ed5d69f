# stack.py: two balls on a vertical line, the upper one thrown down onto the lower one
#
# The lower ball is dropped from rest at height 1, the upper one starts 0.2 above touching it
# with downward speed s. The gap between them and the lower ball's height share the lower ball's
# mass, so the constraints are inertially coupled; at s = 0.2 / sqrt(2) the balls meet exactly
# when the lower one lands, and the upper ball's velocity jumps there.
import sympy as sp

from biped_opt.systems import System

stack = System("stack", ["low", "top"], s="v0", restitution=0.8,
               parameters={"m_low": 1.0, "m_top": 0.25, "r": 0.1, "g": 1.0})
low, top = stack.q
m_low, m_top, r, g = (stack.p[n] for n in ("m_low", "m_top", "r", "g"))
stack.mass_matrix = sp.diag(m_low, m_top)
stack.forces = lambda J: [-m_low * g, -m_top * g]
stack.constraint("ground", low)
stack.constraint("gap", top - low - r)
stack.maneuver("throw", initial={low: 1, top: 1 + r + 0.2, stack.dq[1]: -stack.s},
               terminal=stack.dq[0], armed_after="touchdown", final_mode=(),
               outcome=stack.dq[1], s_range=(0.05, 0.5),
               description="ends at the lower ball's first apex after the first impact; "
                           "outcome the upper ball's velocity then")
SYSTEM = stack

"""husky-cbf's behaviours, one module each behind one interface (base.Behaviour): approach
(set-point line approach, docking, pivot; the point of a slow trajectory), yield_to_movers
(stepping aside, waiting beside a slow reference's point, bracing across a mover's track) and
recovery (progress checker and recovery phases). The arbiter (arbiter.py) chooses among them."""

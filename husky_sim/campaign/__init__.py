"""Campaigns: many generated layouts of scenario families run with one controller, counted by
failure class with exact confidence bounds (husky_sim.campaign.runner, .stats, .report), and
the falsifier that searches a family's parameters for the lowest clearance
(husky_sim.campaign.falsify)."""

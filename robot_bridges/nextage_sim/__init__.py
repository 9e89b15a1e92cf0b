"""nextage_sim back end."""

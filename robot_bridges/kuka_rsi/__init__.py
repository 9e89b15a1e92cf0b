"""kuka_rsi back end."""

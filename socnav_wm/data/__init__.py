"""Rollout data: the Parquet schema, shard writer/reader, and LSTM training windows."""

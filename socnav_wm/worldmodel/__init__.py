"""The world model: observation VAE, latent LSTM, and their training."""

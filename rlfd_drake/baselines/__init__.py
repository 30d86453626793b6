"""The paper's baselines (random, linear RLS, eNAC, FDG, PoWER, pure RL, hybrid)."""

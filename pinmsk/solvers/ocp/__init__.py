"""The optimal-control engine: CasADi + IPOPT direct collocation with exact derivatives (issue 16)."""

"""The plan file (stratawalk.plan/1): the Plan, its independent check, its export."""

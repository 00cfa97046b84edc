"""Task learning: HSMM (eqs. 4-11), GMR (eqs. 15-17), reproduction (eqs. 12-18, 23)."""

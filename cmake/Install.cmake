# install rules and CPack (placeholder)

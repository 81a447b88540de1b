// placeholder: the lead writes main.cpp
int main() { return 0; }

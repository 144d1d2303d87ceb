// Replaced as soon as the first real io source lands.
namespace cloudbake {
int cloudbake_io_placeholder = 0;
}
